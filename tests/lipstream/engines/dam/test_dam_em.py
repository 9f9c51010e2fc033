"""EM training: the sparse E-step against dense lstsq, Gauss-Newton recovering a known DAM,
and the monitor's non-increasing objective."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lipstream.engines.dam import em
from lipstream.engines.dam.modes import Occurrences
from tests.lipstream.engines.dam.dam_synthetic import known_dam, layout

EPS = 1e-4


def _problem(
    seed: int, n_modes: int, degree: int
) -> tuple[np.random.Generator, Occurrences, np.ndarray]:
    rng = np.random.default_rng(seed)
    durations = [list(rng.uniform(0.06, 0.2, size=6)) for _ in range(5)]
    occurrences, _ = layout(durations, fps=100.0)
    mode = rng.integers(0, n_modes, size=len(occurrences.start))
    mode[:n_modes] = np.arange(n_modes)
    return rng, occurrences, mode


def test_design_matrix_is_eq_6_summed_over_occurrences_of_a_mode() -> None:
    _, occurrences, mode = _problem(0, 3, 2)
    sigma = np.array([0.2, 0.35, 0.5])
    settings = em.Settings(degree=2, eps=EPS, tol=1e-12, ridge=0.0)
    n_rows = int((occurrences.first_row + occurrences.rows).max())
    matrix = em.design(occurrences, mode, sigma, n_rows, settings).toarray()
    for k in range(3):
        for m in range(3):
            unit = np.zeros((3, 3, 1))
            unit[k, m, 0] = 1.0
            expected = known_dam(occurrences, mode, sigma, unit, EPS)[:, 0]
            np.testing.assert_allclose(matrix[:, k * 3 + m], expected, atol=1e-9)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_e_step_equals_dense_lstsq(seed: int) -> None:
    rng, occurrences, mode = _problem(seed, 4, 3)
    sigma = rng.uniform(0.1, 0.6, size=4)
    settings = em.Settings(degree=3, eps=EPS, tol=1e-6, ridge=0.0)
    n_rows = int((occurrences.first_row + occurrences.rows).max())
    frames = rng.normal(size=(n_rows, 3))
    matrix = em.design(occurrences, mode, sigma, n_rows, settings)
    dense = matrix.toarray()
    assert np.linalg.matrix_rank(dense) == dense.shape[1]
    expected, *_ = np.linalg.lstsq(dense, frames, rcond=None)
    np.testing.assert_allclose(em.e_step(matrix, frames, 0.0), expected, atol=1e-8)


def test_gauss_newton_recovers_a_known_dam() -> None:
    rng, occurrences, mode = _problem(7, 3, 2)
    sigma = np.array([0.15, 0.3, 0.45])
    coefficients = rng.normal(size=(3, 3, 2))
    frames = known_dam(occurrences, mode, sigma, coefficients, EPS)
    settings = em.Settings(degree=2, eps=EPS, tol=1e-10, ridge=0.0)
    fitted = em.fit(occurrences, mode, 3, frames, settings, n_iter=60, tol=1e-14, sigma_init=0.25)
    np.testing.assert_allclose(fitted.sigma, sigma, atol=1e-4)
    np.testing.assert_allclose(fitted.coefficients, coefficients, atol=1e-3)
    assert fitted.history[-1] < 1e-8 * fitted.history[0]


def test_em_objective_never_increases_on_noisy_curves() -> None:
    rng, occurrences, mode = _problem(11, 4, 4)
    sigma = np.array([0.1, 0.25, 0.4, 0.55])
    frames = known_dam(occurrences, mode, sigma, rng.normal(size=(4, 5, 3)), EPS)
    frames += rng.normal(scale=0.3, size=frames.shape)
    settings = em.Settings(degree=4, eps=EPS, tol=1e-6, ridge=1e-6)
    fitted = em.fit(occurrences, mode, 4, frames, settings, n_iter=15, tol=0.0, sigma_init=1.0)
    history = np.array(fitted.history)
    assert len(history) == 16
    assert np.all(np.diff(history) <= 1e-9 * history[:-1])
    assert history[-1] < history[0]


def test_m_step_never_raises_the_objective_and_lowers_it_from_a_bad_sigma() -> None:
    rng, occurrences, mode = _problem(5, 2, 1)
    sigma = np.array([0.2, 0.4])
    coefficients = rng.normal(size=(2, 2, 1))
    frames = known_dam(occurrences, mode, sigma, coefficients, EPS)
    settings = em.Settings(degree=1, eps=EPS, tol=1e-9, ridge=0.0)
    n_rows = len(frames)
    flat = coefficients.reshape(4, 1)
    bad = np.array([0.9, 0.05])
    start = em.objective(em.design(occurrences, mode, bad, n_rows, settings), flat, frames, 0.0)
    new_sigma, value = em.m_step(occurrences, mode, bad, flat, frames, settings, start)
    assert value < start
    again = em.objective(
        em.design(occurrences, mode, new_sigma, n_rows, settings), flat, frames, 0.0
    )
    assert math.isclose(again, value, rel_tol=1e-12)
    # at the optimum no step helps, and sigma stays
    best = em.objective(em.design(occurrences, mode, sigma, n_rows, settings), flat, frames, 0.0)
    kept, value = em.m_step(occurrences, mode, sigma, flat, frames, settings, best)
    assert value <= best


def test_monitor_refuses_a_rising_objective_and_stops_on_small_gains() -> None:
    monitor = em.ConvergenceMonitor(tol=1e-3, n_iter=10)
    monitor.report(10.0)
    monitor.report(5.0)
    assert not monitor.converged
    with pytest.raises(em.NonMonotoneError):
        monitor.report(5.1)
    monitor.report(4.9999)
    assert monitor.converged
    capped = em.ConvergenceMonitor(tol=0.0, n_iter=2)
    for value in (3.0, 2.0, 1.0):
        assert not capped.converged
        capped.report(value)
    assert capped.converged
