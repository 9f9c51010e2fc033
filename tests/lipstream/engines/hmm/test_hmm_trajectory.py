"""Brand's Eq. 5-6 trajectory: the banded solve against a dense one, fps scaling, windows."""

from __future__ import annotations

import numpy as np
import pytest

from lipstream.engines.hmm import trajectory

DIM = 3


def _states(seed: int, n: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """Random [pose, velocity] means (n, 2D) and full covariances (n, 2D, 2D)."""
    rng = np.random.default_rng(seed)
    means = np.concatenate([rng.normal(size=(n, DIM)), 0.1 * rng.normal(size=(n, DIM))], axis=1)
    factors = rng.normal(size=(n, 2 * DIM, 2 * DIM)) * 0.3
    covariances = factors @ np.swapaxes(factors, 1, 2) + 0.05 * np.eye(2 * DIM)
    return means, covariances


def _dense(means: np.ndarray, covariances: np.ndarray, states: np.ndarray) -> np.ndarray:
    """Eq. 5 built as one dense least-squares system over all T·D unknowns."""
    frames = len(states)
    size = frames * DIM
    hessian, gradient = np.zeros((size, size)), np.zeros(size)
    for t, state in enumerate(states):
        if t == 0:
            select = np.zeros((DIM, size))
            select[:, :DIM] = np.eye(DIM)
            precision = np.linalg.inv(covariances[state][:DIM, :DIM])
            target = means[state][:DIM]
        else:
            select = np.zeros((2 * DIM, size))
            select[:DIM, t * DIM : (t + 1) * DIM] = np.eye(DIM)
            select[DIM:, t * DIM : (t + 1) * DIM] = np.eye(DIM)
            select[DIM:, (t - 1) * DIM : t * DIM] = -np.eye(DIM)
            precision = np.linalg.inv(covariances[state])
            target = means[state]
        hessian += select.T @ precision @ select
        gradient += select.T @ precision @ target
    return np.linalg.solve(hessian, gradient).reshape(frames, DIM)


@pytest.mark.parametrize("seed", range(3))
def test_the_banded_solve_equals_a_dense_solve(seed: int) -> None:
    means, covariances = _states(seed)
    states = np.random.default_rng(seed + 10).integers(0, 4, size=25)
    banded = trajectory.solve(trajectory.dynamics(means, covariances), states)
    np.testing.assert_allclose(banded, _dense(means, covariances, states), atol=1e-8)


def test_pins_hold_the_first_frames_and_the_rest_follows_the_dense_solution() -> None:
    means, covariances = _states(4)
    states = np.repeat([0, 1, 2, 3], 6)
    terms = trajectory.dynamics(means, covariances)
    whole = trajectory.solve(terms, states)
    pinned = trajectory.solve(terms, states[10:], pins=whole[10:12])
    np.testing.assert_allclose(pinned[:2], whole[10:12], atol=1e-6)
    # With its past pinned to the whole solution, the tail's only change is what the
    # dropped state terms of the two pinned frames did: small next to the motion.
    assert np.abs(pinned[2:] - whole[12:]).max() < 0.25 * np.ptp(whole, axis=0).max()


def test_solving_at_a_higher_rate_keeps_the_trajectorys_shape() -> None:
    means, covariances = _states(7)
    states = np.repeat([0, 2, 1, 3, 0], 8)  # 40 frames at the model's rate R
    coarse = trajectory.solve(trajectory.dynamics(means, covariances), states)
    for factor in (2, 3):
        fine_states = np.repeat(states, factor)
        fine = trajectory.solve(trajectory.dynamics(means, covariances, 1.0 / factor), fine_states)
        sampled = fine[::factor]
        # Same shape: strongly correlated per dimension and close in value.
        for d in range(DIM):
            assert np.corrcoef(sampled[:, d], coarse[:, d])[0, 1] > 0.95
        assert np.abs(sampled - coarse).mean() < 0.1 * np.ptp(coarse)
        # Unscaled velocity statistics would demand the per-frame step of R at R·factor:
        wrong = trajectory.solve(trajectory.dynamics(means, covariances, 1.0), fine_states)
        assert np.abs(sampled - coarse).mean() < np.abs(wrong[::factor] - coarse).mean()


def test_uncoupled_terms_drop_only_the_pose_velocity_covariance() -> None:
    means, covariances = _states(9)
    blocky = covariances.copy()
    blocky[:, :DIM, DIM:] = 0.0
    blocky[:, DIM:, :DIM] = 0.0
    states = np.repeat([0, 1, 2, 3], 5)
    np.testing.assert_allclose(
        trajectory.solve(trajectory.dynamics(means, covariances, coupled=False), states),
        _dense(means, blocky, states),
        atol=1e-8,
    )


def test_velocity_statistics_scale_by_the_rate_ratio_as_worked_by_hand() -> None:
    """One pose dimension, learned at R = 40 Hz, solved at f = 60 Hz: ρ = R / f = 2/3, so
    the velocity mean 0.6 becomes 0.4, the cross-covariance 0.3 becomes 0.2 and the velocity
    variance 0.5 becomes 0.5 · 4/9; the pose statistics stay."""
    means = np.array([[1.0, 0.6]])
    covariances = np.array([[[2.0, 0.3], [0.3, 0.5]]])
    terms = trajectory.dynamics(means, covariances, ratio=40.0 / 60.0)
    a, c, e = 2.0, 0.2, 0.5 * 4.0 / 9.0  # the covariance at 60 Hz
    det = a * e - c * c
    p_pose, p_cross, p_velocity = e / det, -c / det, a / det  # its 2 × 2 inverse
    mu, v = 1.0, 0.4
    np.testing.assert_allclose(terms.pose_precision[0], [[1.0 / a]])
    np.testing.assert_allclose(terms.pose_rhs[0], [mu / a])
    np.testing.assert_allclose(terms.g_previous[0], [[p_velocity]])
    np.testing.assert_allclose(terms.g_cross[0], [[-(p_cross + p_velocity)]])
    np.testing.assert_allclose(terms.g_current[0], [[p_pose + 2 * p_cross + p_velocity]])
    pm_pose = p_pose * mu + p_cross * v
    pm_velocity = p_cross * mu + p_velocity * v
    np.testing.assert_allclose(terms.r_previous[0], [-pm_velocity])
    np.testing.assert_allclose(terms.r_current[0], [pm_pose + pm_velocity])
