"""Training on a synthetic HMM with known generating parameters: entropic against Baum-Welch."""

from __future__ import annotations

import numpy as np
import pytest

from lipstream.engines.hmm import em

CYCLE = np.array([[0.85, 0.15, 0, 0], [0, 0.85, 0.15, 0], [0, 0, 0.85, 0.15], [0.15, 0, 0, 0.85]])
MEANS = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]])


def _sample(seed: int, count: int, frames: int) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    sequences = []
    for _ in range(count):
        state, rows = 0, []
        for _ in range(frames):
            rows.append(MEANS[state] + rng.normal(scale=0.5, size=2))
            state = int(rng.choice(4, p=CYCLE[state]))
        sequences.append(np.array(rows))
    return sequences


@pytest.fixture(scope="module")
def fits() -> dict[str, tuple[em.FitResult, em.Statistics]]:
    train, heldout = _sample(1, 8, 80), _sample(2, 4, 80)
    results = {}
    for estimator in em.ESTIMATORS:
        settings = em.Settings(12, estimator=estimator, z=3.0, n_iter=40, tol=1e-6)
        fitted = em.fit(train, settings)
        results[estimator] = (fitted, em.e_step(fitted.parameters, heldout))
    return results


def test_entropic_training_is_sparser_and_more_certain_than_baum_welch(
    fits: dict[str, tuple[em.FitResult, em.Statistics]],
) -> None:
    (entropic, held_e), (conventional, held_c) = fits[em.ENTROPIC], fits[em.BAUM_WELCH]
    assert entropic.parameters.n_states < conventional.parameters.n_states == 12
    perplexity_e = em.perplexity(entropic.parameters, entropic.statistics.occupancy)
    perplexity_c = em.perplexity(conventional.parameters, conventional.statistics.occupancy)
    assert perplexity_e < perplexity_c
    assert held_e.entropy / held_e.frames < held_c.entropy / held_c.frames
    assert (entropic.parameters.transition > 0).sum() < (
        conventional.parameters.transition > 0
    ).sum()


def test_the_log_posterior_never_decreases(
    fits: dict[str, tuple[em.FitResult, em.Statistics]],
) -> None:
    for fitted, _ in fits.values():
        history = np.array(fitted.history)
        assert len(history) > 5
        assert np.all(np.diff(history) >= -1e-7 * np.abs(history[1:]))


def test_the_entropic_model_finds_the_generating_cycle(
    fits: dict[str, tuple[em.FitResult, em.Statistics]],
) -> None:
    parameters = fits[em.ENTROPIC][0].parameters
    # Every true mean is within 0.5 of some state's mean...
    distances = np.linalg.norm(parameters.means[:, None, :] - MEANS[None], axis=2)
    assert distances.min(axis=0).max() < 0.5
    # ...and the learned machine is sparse: most rows keep only a few successors.
    assert np.median((parameters.transition > 1e-6).sum(axis=1)) <= 3
