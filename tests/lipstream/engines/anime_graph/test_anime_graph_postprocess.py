"""Post-processing and clustering: cutoffs, filters, DTW, blending at jumps, merged nodes."""

from __future__ import annotations

import numpy as np
import pytest

from lipstream.engines.anime_graph import AnimeGraphEngine, AnimeGraphModel
from lipstream.engines.anime_graph.blending import JoinKind, PairIndex, plan_join
from lipstream.engines.anime_graph.clustering import cluster_animes
from lipstream.engines.anime_graph.costs import Poses
from lipstream.engines.anime_graph.graph import ClusterGraph
from lipstream.engines.anime_graph.smoothing import (
    energy_below,
    learn_cutoffs,
    lowpass_kernels,
    transition_width,
)
from lipstream.engines.anime_graph.warp import (
    Alignment,
    accumulated_costs,
    dtw_warp,
    dtw_warps,
    frame_costs,
    matched_means,
)
from tests.lipstream.engines.anime_graph.anime_synthetic import make_corpus, make_spans

FPS = 120.0


def _tones(seconds: float, parts: list[tuple[float, float]]) -> np.ndarray:
    times = np.arange(int(seconds * FPS)) / FPS
    return np.asarray(sum(amplitude * np.sin(2 * np.pi * hz * times) for hz, amplitude in parts))


def test_learned_cutoff_keeps_99_percent_of_the_energy() -> None:
    # energy shares: component 0 -> 1 Hz 97.2%, 4 Hz 2.2%, 20 Hz 0.6%: 99% is reached at 4 Hz;
    # component 1 -> 2 Hz 80%, 9 Hz 20%: 99% is reached at 9 Hz.
    curves = [
        np.stack(
            [
                _tones(seconds, [(1.0, 1.0), (4.0, 0.15), (20.0, 0.08)]),
                _tones(seconds, [(2.0, 1.0), (9.0, 0.5)]),
            ],
            axis=1,
        )
        for seconds in (2.0, 3.0, 5.0)
    ]
    cutoffs = learn_cutoffs(curves, FPS, 0.99)
    assert cutoffs == pytest.approx([4.0, 9.0], abs=1e-9)
    kept = energy_below(curves, FPS, cutoffs)
    assert np.all(kept >= 0.99)
    assert np.all(energy_below(curves, FPS, cutoffs - 0.5) < 0.99)


def test_a_still_component_gets_no_cutoff() -> None:
    curves = [np.stack([_tones(2.0, [(3.0, 1.0)]), np.full(int(2 * FPS), 0.25)], axis=1)]
    assert learn_cutoffs(curves, FPS)[1] == FPS / 2


@pytest.mark.parametrize("half_width", [12, 60])
def test_lowpass_kernels_pass_below_and_stop_above_the_cutoff(half_width: int) -> None:
    kernel = lowpass_kernels(np.array([5.0, FPS / 2]), FPS, half_width)
    roll_off = transition_width(FPS, half_width)

    def gain(row: int, hz: float) -> float:
        n = np.arange(-half_width, half_width + 1)
        return float(abs(np.sum(kernel[row] * np.exp(-2j * np.pi * hz * n / FPS))))

    assert gain(0, 0.0) == pytest.approx(1.0, abs=1e-9)
    assert all(gain(0, hz) == pytest.approx(1.0, abs=0.02) for hz in np.linspace(0, 5, 11))
    assert gain(0, 5.0 + 1.2 * roll_off) < 0.02
    assert gain(1, 30.0) == pytest.approx(1.0)


def test_dtw_recovers_a_known_time_warp() -> None:
    source_times = np.arange(41) / 100.0
    target_times = np.arange(61) / 100.0

    def warp(t: np.ndarray) -> np.ndarray:
        return 0.4 * (t / 0.6) ** 2

    features = np.stack([source_times, np.sin(9 * source_times)], axis=1)
    target = np.stack([warp(target_times), np.sin(9 * warp(target_times))], axis=1)
    result = dtw_warp(target, target_times, features, source_times, (0.0, 0.6), (0.0, 0.4))
    probe = np.linspace(0.0, 0.6, 25)
    np.testing.assert_allclose(result(probe), warp(probe), atol=0.011)
    assert result(np.array([0.0, 0.6])).tolist() == [0.0, 0.4]
    assert np.all(np.diff(result(np.linspace(0, 0.6, 200))) >= 0)


def test_dtw_table_matches_the_recurrence_cell_by_cell() -> None:
    cost = np.random.default_rng(3).uniform(0.0, 1.0, (5, 7))
    expected = np.full((6, 8), np.inf)
    expected[0, 0] = 0.0
    for i in range(5):
        for j in range(7):
            best = min(expected[i, j], expected[i, j + 1], expected[i + 1, j])
            expected[i + 1, j + 1] = cost[i, j] + best
    np.testing.assert_allclose(accumulated_costs(cost), expected[1:, 1:], rtol=1e-12)


def _monotone_paths(n: int, m: int) -> list[list[tuple[int, int]]]:
    """Every DTW path from (0, 0) to (n-1, m-1) with steps (1,0), (0,1), (1,1)."""
    if n == 1 and m == 1:
        return [[(0, 0)]]
    paths = []
    for di, dj in ((1, 0), (0, 1), (1, 1)):
        if n - di >= 1 and m - dj >= 1:
            paths += [p + [(n - 1, m - 1)] for p in _monotone_paths(n - di, m - dj)]
    return paths


@pytest.mark.parametrize("shape", [(2, 2), (3, 5), (5, 3), (4, 4)])
def test_dtw_matches_each_target_frame_along_the_cheapest_of_all_paths(
    shape: tuple[int, int],
) -> None:
    n, m = shape
    rng = np.random.default_rng(n * 10 + m)
    target, source = rng.normal(size=(n, 3)), rng.normal(size=(m, 3))
    source_times = 2.0 + np.arange(m) / 100.0
    cost = np.linalg.norm(target[:, None] - source[None], axis=2)
    best = min(_monotone_paths(n, m), key=lambda path: sum(cost[i, j] for i, j in path))
    expected = [np.mean([source_times[j] for i, j in best if i == row]) for row in range(n)]
    table = accumulated_costs(frame_costs(target, source))
    np.testing.assert_allclose(matched_means(table, source_times), expected, rtol=1e-12)
    problem = Alignment(
        target,
        0.1 + np.arange(n) / 100.0,
        source,
        source_times,
        (0.1, 0.1 + n / 100.0),
        (2.0, 2.0 + m / 100.0),
    )
    alone = dtw_warps([problem])[0]
    inside = [(t, s) for t, s in zip(problem.target_times, expected) if 0.1 < t < 0.1 + n / 100.0]
    assert alone.target.tolist() == [0.1] + [t for t, _ in inside] + [0.1 + n / 100.0]
    np.testing.assert_allclose(
        alone.source[1:-1],
        np.maximum.accumulate(np.clip([s for _, s in inside], 2.0, 2.0 + m / 100.0)),
        rtol=1e-12,
    )


def test_short_problems_are_warped_linearly() -> None:
    rng = np.random.default_rng(4)
    problem = Alignment(
        rng.normal(size=(1, 3)),
        np.array([0.1]),
        rng.normal(size=(5, 3)),
        2.0 + np.arange(5) / 100.0,
        (0.1, 0.11),
        (2.0, 2.05),
    )
    warp = dtw_warps([problem])[0]
    assert warp.target.tolist() == [0.1, 0.11]
    assert warp.source.tolist() == [2.0, 2.05]


@pytest.fixture(scope="module")
def model() -> AnimeGraphModel:
    return AnimeGraphEngine(clusters=30).fit(make_corpus(seed=3, n_utterances=24))


def _join_jumps(model: AnimeGraphModel, seed: int, blend: bool, smooth: bool) -> np.ndarray:
    """Position jump at every join that is not seamless: the frame step across the join less
    the mean of the steps on either side (the motion's own speed), as a pose distance."""
    spans = make_spans(np.random.default_rng(seed), 18)
    synthesizer = model.start(fps=FPS, blend=blend, smooth=smooth)
    synthesizer.feed(spans)
    steps = np.diff(synthesizer.finish().astype(np.float64), axis=0)
    track = synthesizer.track
    return np.array(
        [
            np.linalg.norm(steps[k] - (steps[k - 1] + steps[k + 1]) / 2.0)
            for index, join in enumerate(track.joins)
            if join.kind is not JoinKind.SEAMLESS
            for k in [int(np.ceil(track.placements[index + 1].start * FPS)) - 1]
        ]
    )


def test_joins_jump_no_further_than_the_recordings_step(model: AnimeGraphModel) -> None:
    recordings = make_corpus(seed=3, n_utterances=24).utterances
    recorded = max(np.linalg.norm(np.diff(u.frames, axis=0), axis=1).max() for u in recordings)

    def worst(blend: bool, smooth: bool) -> float:
        jumps = np.concatenate([_join_jumps(model, seed, blend, smooth) for seed in range(6)])
        assert len(jumps) > 20
        return float(jumps.max() / recorded)

    assert worst(blend=True, smooth=False) <= 1.0
    assert worst(blend=True, smooth=True) <= 1.0
    assert worst(blend=False, smooth=False) > 2.0, "joined raw, fragments should jump further"


def test_kmeans_representatives_are_the_members_nearest_their_means() -> None:
    rng = np.random.default_rng(0)
    centres = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0]])
    points = np.concatenate([centre + rng.normal(0, 0.5, (20, 2)) for centre in centres])
    assignment, representative = cluster_animes(points, 3, seed=0)
    groups = [set(np.flatnonzero(assignment == c).tolist()) for c in range(3)]
    assert sorted(map(min, groups)) == [0, 20, 40]
    assert all(len(group) == 20 for group in groups)
    for cluster, anime in enumerate(representative):
        members = np.flatnonzero(assignment == cluster)
        mean = points[members].mean(axis=0)
        nearest = members[np.argmin(np.linalg.norm(points[members] - mean, axis=1))]
        assert anime == nearest
    assert representative.tolist() == sorted(representative.tolist())


def test_merged_nodes_keep_every_label_audio_feature_and_edge() -> None:
    rng = np.random.default_rng(1)
    labels = rng.integers(0, 5, 60).astype(np.int16)
    utterance = np.repeat(np.arange(6), 10).astype(np.int32)
    successor = np.where(
        np.append(utterance[1:] == utterance[:-1], False), np.arange(1, 61), -1
    ).astype(np.int32)
    assignment = rng.integers(0, 8, 60)
    representative = np.array([np.flatnonzero(assignment == c)[0] for c in range(8)])
    graph = ClusterGraph.build(assignment, representative, labels, successor, 5)
    for anime in range(60):
        assert graph.has_label(np.array([assignment[anime]]), int(labels[anime]))[0]
        if successor[anime] >= 0:
            assert graph.is_edge(
                np.array([assignment[anime]]), np.array([assignment[successor[anime]]])
            )[0]
    edges = {
        (int(assignment[a]), int(assignment[successor[a]])) for a in range(60) if successor[a] >= 0
    }
    assert sum(len(graph.successors_of(np.array([c]))[1]) for c in range(8)) == len(edges)
    summaries = rng.normal(size=(60, 3))
    query = rng.normal(size=3)
    for cluster in range(8):
        for label in range(5):
            members = np.flatnonzero((assignment == cluster) & (labels == label))
            if len(members):
                expected = np.linalg.norm(summaries[members] - query, axis=1).min()
                got = graph.audio_costs(np.array([cluster]), label, query, summaries)[0]
                assert got == pytest.approx(expected)
                assert graph.members(cluster, label).tolist() == members.tolist()


def test_to_channels_is_the_reconstruction_clipped_to_the_recorded_range(
    model: AnimeGraphModel,
) -> None:
    rng = np.random.default_rng(5)
    coefficients = 3.0 * rng.normal(size=(40, model.n_components))  # far outside, often
    expected = np.clip(
        coefficients @ model.basis.components + model.basis.mean,
        model.channel_low,
        model.channel_high,
    ).astype(np.float32)
    frames = model.to_channels(coefficients)
    assert frames.dtype == np.float32 and np.array_equal(frames, expected)
    assert np.any(frames == model.channel_low.astype(np.float32))
    assert np.any(frames == model.channel_high.astype(np.float32))


@pytest.mark.parametrize("dimensions", [3, 8, 13, 21])
def test_a_pair_join_takes_the_first_cheapest_meeting_as_numpy_ranks_it(dimensions: int) -> None:
    rng = np.random.default_rng(dimensions)
    first, last = rng.normal(size=(2, 60, dimensions))
    last[3] = last[7] = (last[59] + first[40]) / 2.0  # tied cheapest for the join 59 -> 40
    successor = np.append(np.arange(1, 60), -1)
    pairs = PairIndex.build(np.zeros(60, dtype=np.int64), successor, 1)
    poses = Poses(first, last, successor)
    for left, right in [(59, 40), (10, 20), (58, 5)]:
        candidates = pairs.pairs(0, 0)
        meeting = last[candidates]
        cost = np.linalg.norm(meeting - last[left], axis=1) + np.linalg.norm(
            meeting - first[right], axis=1
        )
        expected = int(candidates[int(np.argmin(cost))])
        join = plan_join(left, right, poses, lambda: ((0, 0), pairs), None, True)
        assert (join.kind, join.left_example, join.right_example) == (
            JoinKind.PAIR,
            expected,
            expected + 1,
        )
    assert plan_join(59, 40, poses, lambda: ((0, 0), pairs), None, True).left_example == 3


def test_causal_frames_are_the_track_followed_by_the_damped_filter(
    model: AnimeGraphModel,
) -> None:
    spans = make_spans(np.random.default_rng(2), 12)
    synthesizer = model.start(fps=FPS, causal=True, lead_ms=40.0)
    streamed = []
    for span in spans:
        synthesizer.feed([span])
        streamed.append(synthesizer.frames())
    frames = np.concatenate([*streamed, synthesizer.finish()])
    times = np.arange(len(frames)) / FPS
    lead = model.causal_shift_s(40.0)
    targets = synthesizer.track.evaluate(
        np.minimum(times + lead, spans[-1].end), left_continuous=True
    )
    # the filter stepped frame by frame in closed form, from rest on the first target
    x, v = targets[0].copy(), np.zeros(model.n_components)
    values = [x.copy()]
    for row in range(1, len(times)):
        omega, dt = model.causal_omegas, times[row] - times[row - 1]
        error = x - targets[row]
        pull = v + omega * error
        decay = np.exp(-omega * dt)
        x, v = targets[row] + (error + pull * dt) * decay, (v - omega * pull * dt) * decay
        values.append(x.copy())
    expected = model.to_channels(np.array(values))
    assert frames.shape == expected.shape
    assert np.abs(frames.astype(np.float64) - expected).max() < 1e-5
