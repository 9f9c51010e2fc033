"""The hmm synthesizer's compiled steps against straightforward numpy on small cases."""

from __future__ import annotations

import numpy as np

from lipstream.engines.hmm import kernels, trajectory
from lipstream.numerics.basis import MotionBasis
from lipstream.numerics.trellis import FixedLagViterbi, predecessors

EPS = 1e-9
STATES, DIM = 5, 3


def _spans(rng: np.random.Generator, count: int, categories: int) -> np.ndarray:
    """(start, phoneme row, emotion row) rows with increasing starts from 0."""
    starts = np.concatenate([[0.0], np.cumsum(rng.uniform(0.02, 0.2, count - 1))])
    phonemes = rng.integers(0, categories - 2, count)
    moods = rng.integers(categories - 2, categories, count)
    return np.stack([starts, phonemes, moods], axis=1).astype(np.float64)


def test_emissions_add_each_frames_span_categories_and_the_audio_terms() -> None:
    rng = np.random.default_rng(0)
    categories = rng.normal(size=(8, STATES))
    spans = _spans(rng, 9, len(categories))
    hmm_fps, first, stop = 40.0, 3, 40
    terms, heard_from = rng.normal(size=(10, STATES)), 20
    out = np.empty((stop - first, STATES))
    kernels.emissions(spans, len(spans), first, hmm_fps, categories, 7, terms, heard_from, out)
    for j in range(first, stop):  # the span with start < j / R <= end, frame 0 the first
        time = j / hmm_fps
        span = max([k for k in range(len(spans)) if spans[k, 0] < time - EPS], default=0)
        expected = categories[int(spans[span, 1])] + categories[int(spans[span, 2])]
        if heard_from <= j < heard_from + len(terms):
            expected = expected + terms[j - heard_from]
        np.testing.assert_allclose(out[j - first], expected, rtol=0, atol=1e-12)
    kernels.emissions(spans, 0, first, hmm_fps, categories, 7, terms[:0], 0, out)
    np.testing.assert_array_equal(out, np.broadcast_to(categories[7], out.shape))


def test_decode_equals_emissions_pushed_through_the_decoder() -> None:
    rng = np.random.default_rng(1)
    transition = rng.dirichlet(np.ones(STATES), size=STATES)
    transition[transition < 0.15] = 0.0
    transition /= transition.sum(axis=1, keepdims=True)
    with np.errstate(divide="ignore"):
        log_start, log_transition = np.log(np.full(STATES, 1 / STATES)), np.log(transition)
    categories = rng.normal(size=(8, STATES))
    spans = _spans(rng, 12, len(categories))
    emissions = np.empty((60, STATES))
    kernels.emissions(spans, len(spans), 0, 40.0, categories, 7, emissions[:0], 0, emissions)
    for lag in (None, 0, 3):
        reference = FixedLagViterbi(log_start, log_transition, lag)
        expected = np.concatenate([reference.push(emissions[:25]), reference.push(emissions[25:])])
        decoder = FixedLagViterbi(log_start, log_transition, lag)
        out, count = np.zeros(200, dtype=np.int64), 0
        for first, stop in ((0, 25), (25, 60)):
            decoding = decoder.reserve(stop - first)
            count += kernels.decode(
                spans,
                len(spans),
                first,
                stop,
                40.0,
                categories,
                7,
                emissions[:0],
                0,
                decoding,
                out,
                count,
            )
        np.testing.assert_array_equal(out[:count], expected)
        assert (decoder.frames, decoder.oldest) == (reference.frames, reference.oldest)


def _raw(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Random [pose, velocity] means (N, 2D) and full covariances (N, 2D, 2D)."""
    rng = np.random.default_rng(seed)
    means = np.concatenate(
        [rng.normal(size=(STATES, DIM)), 0.1 * rng.normal(size=(STATES, DIM))], 1
    )
    factors = rng.normal(size=(STATES, 2 * DIM, 2 * DIM)) * 0.3
    return means, factors @ np.swapaxes(factors, 1, 2) + 0.05 * np.eye(2 * DIM)


def test_a_solved_block_is_the_trajectory_solve_of_its_frames_with_the_pins() -> None:
    terms = trajectory.dynamics(*_raw(2), 0.5)
    rng = np.random.default_rng(2)
    states = rng.integers(0, STATES, 30)
    ratio = 40.0 / 60.0
    curve = np.zeros((40, DIM))
    curve[:6] = rng.normal(size=(6, DIM))
    code = kernels.solve_block(states, len(states), ratio, curve, 4, 6, 14, 20, terms.blocks)
    assert code == -1
    frame_states = states[np.minimum(np.floor(np.arange(4, 20) * ratio + EPS).astype(int), 29)]
    expected = trajectory.solve(terms, frame_states, curve[4:6])
    np.testing.assert_allclose(curve[6:14], expected[2:10], rtol=0, atol=1e-12)
    assert not curve[14:].any()


def test_the_recursion_in_place_follows_its_state_from_the_frame_before() -> None:
    terms = trajectory.dynamics(*_raw(3), 0.5, coupled=False)
    rng = np.random.default_rng(3)
    states = rng.integers(0, STATES, 12)
    ratio = 40.0 / 120.0
    curve = np.zeros((36, DIM))
    arguments = (terms.current_inverse, terms.g_cross, terms.r_current, terms.pose_mean)
    kernels.recurse(states, len(states), ratio, curve, 0, 20, *arguments)
    kernels.recurse(states, len(states), ratio, curve, 20, 36, *arguments)
    expected = [terms.pose_mean[states[0]]]
    for t in range(1, 36):
        state = states[min(int(np.floor(t * ratio + EPS)), 11)]
        step = terms.r_current[state] - terms.g_cross[state] @ expected[-1]
        expected.append(np.linalg.solve(terms.g_current[state], step))
    np.testing.assert_allclose(curve, np.array(expected), rtol=0, atol=1e-9)


def test_output_frames_hold_each_trajectory_frame_back_in_channel_space() -> None:
    rng = np.random.default_rng(4)
    basis = MotionBasis(rng.normal(size=7), rng.normal(size=(DIM, 7)))
    curve = rng.normal(size=(50, DIM))
    step = 120.0 / 50.0  # trajectory at 120 Hz, output at 50 fps
    frames = kernels.output_frames(curve, 30, 5, 20, step, basis.components, basis.mean)
    rows = [int(np.floor(i * step + EPS)) for i in range(5, 20)]
    solved = [row for row in rows if row < 30]  # frame 13 would need row 31
    assert len(frames) == len(solved) == 8
    expected = (curve[solved] @ basis.components + basis.mean).astype(np.float32)
    np.testing.assert_allclose(frames, expected, rtol=0, atol=1e-6)
    assert frames.dtype == np.float32


def test_predecessors_list_every_possible_transition_into_each_state() -> None:
    transition = np.array([[0.5, 0.5, 0.0], [0.0, 0.2, 0.8], [1.0, 0.0, 0.0]])
    with np.errstate(divide="ignore"):
        offsets, into = predecessors(np.log(transition))
    found = [sorted(into[offsets[j] : offsets[j + 1]].tolist()) for j in range(3)]
    assert found == [[0, 2], [0, 1], [1]]
