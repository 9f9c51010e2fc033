"""The motion basis keeps the variance share of the total or of every channel."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.decomposition import PCA

from lipstream.numerics.basis import (
    BLAS,
    IN_ORDER,
    MotionBasis,
    basis_frames,
    channel_shares,
    fit_basis,
)


def _frames(seed: int = 0) -> np.ndarray:
    """Three independent sources: two loud ones over four channels, one quiet one that
    alone drives the fifth channel (like mouthClose beside the jaw and brows)."""
    rng = np.random.default_rng(seed)
    loud = rng.normal(size=(4000, 2)) * [3.0, 2.0]
    quiet = rng.normal(size=(4000, 1)) * 0.3
    mixing = np.array([[1.0, 0.5, 0.0, 0.2, 0.0], [0.0, 0.4, 1.0, 0.7, 0.0]])
    return np.asarray(loud @ mixing + quiet @ np.array([[0.0, 0.0, 0.0, 0.0, 1.0]]))


def test_channel_shares_match_the_reconstruction_of_each_channel() -> None:
    frames = _frames()
    pca = PCA(svd_solver="full").fit(frames)
    shares = channel_shares(pca.explained_variance_, pca.components_)
    for k in range(1, 6):
        truncated = PCA(n_components=k, svd_solver="full").fit(frames)
        rebuilt = truncated.inverse_transform(truncated.transform(frames))
        residual = ((frames - rebuilt) ** 2).sum(axis=0) / (len(frames) - 1)
        expected = 1.0 - residual / frames.var(axis=0, ddof=1)
        np.testing.assert_allclose(shares[k - 1], expected, atol=1e-9)


@pytest.mark.parametrize(("per_channel", "components"), [(False, 2), (True, 3)])
def test_the_quiet_channel_needs_its_own_component_only_per_channel(
    per_channel: bool, components: int
) -> None:
    frames = _frames()
    basis, explained = fit_basis(frames, 0.95, per_channel)
    assert basis.n_components == components
    total = PCA(svd_solver="full").fit(frames).explained_variance_ratio_
    assert explained == pytest.approx(total[:components].sum())
    quiet = frames[:, 4] - frames[:, 4].mean()
    kept = basis.reconstruct(basis.project(frames))[:, 4] - basis.mean[4]
    share = 1.0 - np.var(quiet - kept) / np.var(quiet)
    assert (share > 0.95) == per_channel


def test_a_channel_that_never_moves_needs_no_component() -> None:
    frames = np.column_stack([_frames()[:, :2], np.full(4000, 0.25)])
    basis, _ = fit_basis(frames, 0.99)
    assert basis.n_components == 2


def test_reconstruct_is_the_product_plus_the_mean_and_leaves_its_input() -> None:
    rng = np.random.default_rng(2)
    basis = MotionBasis(rng.normal(size=5), np.linalg.qr(rng.normal(size=(5, 3)))[0].T)
    coefficients = rng.normal(size=(7, 3))
    kept = coefficients.copy()
    frames = basis.reconstruct(coefficients)
    assert np.array_equal(frames, coefficients @ basis.components + basis.mean)
    assert np.array_equal(coefficients, kept)


def _coefficients_and_basis(seed: int, rows: int = 40) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    components = rng.normal(size=(6, 11))
    return rng.normal(size=(rows, 6)), components, rng.normal(size=11)


NO_BOUNDS = np.empty(0)


@pytest.mark.parametrize("seed", range(3))
def test_basis_frames_by_blas_are_numpys_product_plus_the_mean_to_the_bit(seed: int) -> None:
    values, components, mean = _coefficients_and_basis(seed)
    frames = basis_frames(values, components, mean, NO_BOUNDS, NO_BOUNDS, BLAS)
    expected = MotionBasis(mean, components).reconstruct(values).astype(np.float32)
    assert frames.dtype == np.float32
    assert np.array_equal(frames, expected)


@pytest.mark.parametrize("seed", range(3))
def test_basis_frames_in_order_add_the_components_one_by_one(seed: int) -> None:
    values, components, mean = _coefficients_and_basis(seed)
    total = np.zeros((len(values), components.shape[1]))
    for component in range(len(components)):
        total = total + values[:, component, None] * components[component]
    frames = basis_frames(values, components, mean, NO_BOUNDS, NO_BOUNDS, IN_ORDER)
    assert np.array_equal(frames, (total + mean).astype(np.float32))
    blas = basis_frames(values, components, mean, NO_BOUNDS, NO_BOUNDS, BLAS)
    np.testing.assert_allclose(frames, blas, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("summation", [BLAS, IN_ORDER])
def test_basis_frames_hold_each_channel_inside_its_bounds(summation: int) -> None:
    values, components, mean = _coefficients_and_basis(3)
    low, high = np.full(11, -1.5), np.full(11, 2.0)
    low[0], high[0] = -np.inf, np.inf
    frames = basis_frames(values, components, mean, low, high, summation)
    unbounded = values @ components + mean
    expected = np.clip(unbounded, low, high).astype(np.float32)
    np.testing.assert_allclose(frames, expected, rtol=1e-6, atol=1e-6)
    assert (unbounded[:, 1:] < low[1:]).any() and (unbounded[:, 1:] > high[1:]).any()
    assert frames[:, 1:].min() == -1.5 and frames[:, 1:].max() == 2.0
    assert frames[:, 0].min() < -1.5 and frames[:, 0].max() > 2.0


@pytest.mark.parametrize("summation", [BLAS, IN_ORDER])
def test_basis_frames_of_no_rows_are_empty(summation: int) -> None:
    _, components, mean = _coefficients_and_basis(0)
    frames = basis_frames(np.zeros((0, 6)), components, mean, NO_BOUNDS, NO_BOUNDS, summation)
    assert frames.shape == (0, 11) and frames.dtype == np.float32
