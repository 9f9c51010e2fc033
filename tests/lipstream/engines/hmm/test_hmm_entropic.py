"""The entropic MAP estimator against a numerical optimizer of the same objective."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize

from lipstream.engines.hmm.entropic import entropic_map, extinct, map_covariance, objective


def _numerical_optimum(omega: np.ndarray, z: float, seed: int) -> np.ndarray:
    """SLSQP on the simplex from several starts: the best objective found."""
    rng = np.random.default_rng(seed)
    best = None
    for _ in range(8):
        result = minimize(
            lambda theta: -objective(theta, omega, z),
            rng.dirichlet(np.ones(len(omega))),
            method="SLSQP",
            bounds=[(1e-15, 1.0)] * len(omega),
            constraints=[{"type": "eq", "fun": lambda theta: theta.sum() - 1.0}],
            options={"maxiter": 500, "ftol": 1e-15},
        )
        if best is None or result.fun < best.fun:
            best = result
    assert best is not None
    return np.asarray(best.x / best.x.sum())


@pytest.mark.parametrize("z", [1.0, 3.0, -1.0, -0.5])
@pytest.mark.parametrize("scale", [0.01, 0.5, 5.0, 500.0])
def test_entropic_map_matches_a_numerical_optimizer(z: float, scale: float) -> None:
    omega = np.random.default_rng(int(scale * 100) + int(z * 7) + 10).random(4) * scale
    theta = entropic_map(omega, z)
    found = _numerical_optimum(omega, z, seed=3)
    assert theta.sum() == pytest.approx(1.0)
    assert objective(theta, omega, z) >= objective(found, omega, z) - 1e-9
    np.testing.assert_allclose(theta, found, atol=2e-3)


def test_entropic_map_sharpens_and_its_negative_scale_flattens() -> None:
    omega = np.array([6.0, 3.0, 1.0])
    plain = omega / omega.sum()
    sharp, flat = entropic_map(omega, 1.0), entropic_map(omega, -1.0)

    def entropy(p: np.ndarray) -> float:
        return -float(np.sum(p * np.log(p)))

    assert entropy(sharp) < entropy(plain) < entropy(flat)
    assert np.allclose(entropic_map(omega, 0.0), plain)


def test_small_evidence_is_stable_and_zero_evidence_is_extinct() -> None:
    theta = entropic_map(np.array([1e-6, 2e-6, 0.0, 5e-7]), 1.0)
    assert np.isfinite(theta).all() and theta.sum() == pytest.approx(1.0)
    assert theta[2] == 0.0
    assert theta[1] == theta.max()


def test_extinction_trims_parameters_whose_evidence_cannot_pay_for_them() -> None:
    theta = np.array([0.7, 0.299, 0.001])
    omega = np.array([70.0, 30.0, 1e-5])
    # ω/θ < −Z log θ: 0.01 < 6.9 for the last; 100 > 0.36 and 100 > 1.2 keep the others.
    np.testing.assert_array_equal(extinct(theta, omega, 1.0), [False, False, True])
    assert not extinct(theta, omega, 0.0).any()


def test_map_covariance_shrinks_the_scatter_by_the_prior_scale() -> None:
    scatter = np.array([[4.0, 1.0], [1.0, 2.0]])
    np.testing.assert_allclose(map_covariance(scatter, 9.0, 1.0), scatter / 10.0)
