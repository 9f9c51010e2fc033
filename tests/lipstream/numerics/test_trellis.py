"""Log-space trellis kernels against brute-force enumeration of every state path."""

from __future__ import annotations

import itertools
from collections.abc import Iterator

import numpy as np
import pytest
from scipy.special import logsumexp

from lipstream.numerics.trellis import FixedLagViterbi, advance, forward_backward, viterbi


def _tiny_model(seed: int, states: int = 3, frames: int = 6) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(seed)
    start = rng.dirichlet(np.ones(states))
    transition = rng.dirichlet(np.ones(states), size=states)
    transition[0, -1] = 0.0  # a forbidden transition
    transition /= transition.sum(axis=1, keepdims=True)
    emission = rng.normal(scale=2.0, size=(frames, states))
    return start, transition, emission


def _paths(
    start: np.ndarray, transition: np.ndarray, emission: np.ndarray
) -> Iterator[tuple[np.ndarray, float]]:
    """Every path with its joint log-probability log P(path, X)."""
    with np.errstate(divide="ignore"):
        log_start, log_transition = np.log(start), np.log(transition)
    frames, states = emission.shape
    for path in itertools.product(range(states), repeat=frames):
        score = log_start[path[0]] + emission[0, path[0]]
        for t in range(1, frames):
            score += log_transition[path[t - 1], path[t]] + emission[t, path[t]]
        yield np.array(path), score


@pytest.mark.parametrize("seed", range(4))
def test_viterbi_equals_the_best_enumerated_path(seed: int) -> None:
    start, transition, emission = _tiny_model(seed)
    best_path, best_score = max(_paths(start, transition, emission), key=lambda item: item[1])
    with np.errstate(divide="ignore"):
        path, score = viterbi(np.log(start), np.log(transition), emission)
    np.testing.assert_array_equal(path, best_path)
    assert score == pytest.approx(best_score, abs=1e-9)


@pytest.mark.parametrize("seed", range(4))
def test_forward_backward_equals_enumerated_marginals_and_entropy(seed: int) -> None:
    start, transition, emission = _tiny_model(seed)
    frames, states = emission.shape
    paths = list(_paths(start, transition, emission))
    scores = np.array([score for _, score in paths])
    log_likelihood = logsumexp(scores)
    weights = np.exp(scores - log_likelihood)
    gamma = np.zeros((frames, states))
    pairs = np.zeros((states, states))
    for (path, _), weight in zip(paths, weights):
        gamma[np.arange(frames), path] += weight
        for t in range(1, frames):
            pairs[path[t - 1], path[t]] += weight
    positive = weights[weights > 0]
    entropy = -float(np.sum(positive * np.log(positive)))
    with np.errstate(divide="ignore"):
        posterior = forward_backward(np.log(start), transition, emission)
    assert posterior.log_likelihood == pytest.approx(log_likelihood, abs=1e-9)
    np.testing.assert_allclose(posterior.gamma, gamma, atol=1e-10)
    np.testing.assert_allclose(posterior.transitions, pairs, atol=1e-10)
    assert posterior.entropy == pytest.approx(entropy, abs=1e-9)


def test_forward_backward_keeps_paths_through_states_far_below_the_best() -> None:
    """A state reachable only from a state ~1000 nats below the best must keep its mass."""
    start = np.array([0.5, 0.5, 0.0])
    transition = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    emission = np.array([[0.0, -1000.0, -5.0], [0.0, -5.0, -1000.0], [-2000.0, -5.0, 0.0]])
    log_start = np.where(start > 0, np.log(np.where(start > 0, start, 1.0)), -np.inf)
    paths = [(p, s) for p, s in _paths(start, transition, emission) if np.isfinite(s)]
    expected = logsumexp([s for _, s in paths])
    posterior = forward_backward(log_start, transition, emission)
    assert posterior.log_likelihood == pytest.approx(expected, abs=1e-9)
    assert posterior.gamma.sum(axis=1) == pytest.approx(np.ones(3))


def _greedy(start: np.ndarray, transition: np.ndarray, emission: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore"):
        log_start, log_transition = np.log(start), np.log(transition)
    path = [int(np.argmax(log_start + emission[0]))]
    for t in range(1, len(emission)):
        path.append(int(np.argmax(log_transition[path[-1]] + emission[t])))
    return np.array(path)


def _decode(decoder: FixedLagViterbi, emission: np.ndarray, cuts: list[int]) -> np.ndarray:
    pieces = []
    bounds = [0, *sorted(set(cuts)), len(emission)]
    for first, stop in itertools.pairwise(bounds):
        pieces.append(decoder.push(emission[first:stop]))
    pieces.append(decoder.finish())
    return np.concatenate(pieces)


@pytest.mark.parametrize("seed", range(3))
def test_fixed_lag_viterbi_without_a_lag_limit_is_viterbi_in_any_chunking(seed: int) -> None:
    start, transition, emission = _tiny_model(seed, states=4, frames=40)
    with np.errstate(divide="ignore"):
        log_start, log_transition = np.log(start), np.log(transition)
    full, _ = viterbi(log_start, log_transition, emission)
    for cuts in ([], [1, 7, 8, 30], list(range(1, 40))):
        decoded = _decode(FixedLagViterbi(log_start, log_transition, None), emission, cuts)
        np.testing.assert_array_equal(decoded, full)


@pytest.mark.parametrize("seed", range(3))
def test_lag_zero_is_greedy_and_any_lag_is_chunking_independent(seed: int) -> None:
    start, transition, emission = _tiny_model(seed, states=4, frames=30)
    with np.errstate(divide="ignore"):
        log_start, log_transition = np.log(start), np.log(transition)
    greedy = _decode(FixedLagViterbi(log_start, log_transition, 0), emission, [])
    np.testing.assert_array_equal(greedy, _greedy(start, transition, emission))
    for lag in (0, 1, 3):
        whole = _decode(FixedLagViterbi(log_start, log_transition, lag), emission, [])
        assert len(whole) == len(emission)
        for cuts in ([5, 6, 17], list(range(1, 30, 2))):
            chunked = _decode(FixedLagViterbi(log_start, log_transition, lag), emission, cuts)
            np.testing.assert_array_equal(chunked, whole)


def test_a_lag_limit_commits_frames_that_lag_behind_and_merges_commit_early() -> None:
    start, transition, emission = _tiny_model(5, states=4, frames=30)
    with np.errstate(divide="ignore"):
        log_start, log_transition = np.log(start), np.log(transition)
    decoder = FixedLagViterbi(log_start, log_transition, 3)
    for t in range(len(emission)):
        decoder.push(emission[t : t + 1])
        assert decoder.oldest >= t + 1 - 3  # never more than 3 frames undecided
    # A near-deterministic chain with sharp emissions: survivors merge at every frame.
    sharp = np.full((20, 3), -50.0)
    sharp[np.arange(20), np.arange(20) % 3] = 0.0
    cycle = np.roll(np.eye(3), 1, axis=1) * 0.98 + 0.01
    decoder = FixedLagViterbi(np.log(np.full(3, 1 / 3)), np.log(cycle), None)
    committed = decoder.push(sharp)
    assert len(committed) >= 19  # all but (at most) the newest frame, with no lag limit
    np.testing.assert_array_equal(committed, (np.arange(20) % 3)[: len(committed)])


def test_fixed_lag_viterbi_on_a_sparse_chain_is_the_dense_viterbi() -> None:
    rng = np.random.default_rng(7)
    states = 6
    transition = rng.dirichlet(np.ones(states), size=states)
    transition[rng.random((states, states)) < 0.6] = 0.0  # most transitions impossible
    transition[np.arange(states), np.arange(states)] += 0.1  # every row keeps one
    transition[:, 3] = 0.0  # a state nothing leads into
    transition /= transition.sum(axis=1, keepdims=True)
    emission = rng.normal(scale=2.0, size=(50, states))
    with np.errstate(divide="ignore"):
        log_start, log_transition = np.log(np.full(states, 1 / states)), np.log(transition)
    full, _ = viterbi(log_start, log_transition, emission)
    for cuts in ([], [1, 9, 30], list(range(1, 50, 3))):
        decoded = _decode(FixedLagViterbi(log_start, log_transition, None), emission, cuts)
        np.testing.assert_array_equal(decoded, full)


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("cuts", [[], [1, 2, 3, 4, 5, 6], [5]])
def test_advance_on_the_reserved_state_decodes_the_best_enumerated_path(
    seed: int, cuts: list[int]
) -> None:
    """Compiled callers: ``reserve`` then ``advance`` per chunk, states written at an offset."""
    start, transition, emission = _tiny_model(seed, frames=7)
    best_path, _ = max(_paths(start, transition, emission), key=lambda item: item[1])
    with np.errstate(divide="ignore"):
        log_start, log_transition = np.log(start), np.log(transition)
    for lag, expected in ((None, best_path), (0, _greedy(start, transition, emission))):
        decoder = FixedLagViterbi(log_start, log_transition, lag)
        committed, count = np.full(len(emission) + 1, -1, dtype=np.int64), 0
        bounds = [0, *cuts, len(emission)]
        for first, stop in itertools.pairwise(bounds):
            decoding = decoder.reserve(stop - first)
            count += advance(decoding, emission[first:stop], committed, count)
            assert (decoder.frames, decoding.position[0]) == (stop, stop)
        tail = decoder.finish()
        np.testing.assert_array_equal(np.concatenate([committed[:count], tail]), expected)
        assert committed[len(emission)] == -1  # nothing written past the frames
