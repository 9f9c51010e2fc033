"""The motion basis keeps the variance share of the total or of every channel."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.decomposition import PCA

from lipstream.numerics.basis import MotionBasis, channel_shares, fit_basis


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
