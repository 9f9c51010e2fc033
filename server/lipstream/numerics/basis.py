"""The motion basis: PCA of every training frame, keeping a share of the variance.

Sketch: sklearn's PCA on all frames (n_frames, n_channels), keeping the
fewest components that explain ``variance`` (95% by default, as in the
paper) of the variance. By default the share must be reached by every
channel on its own, not only by the total: the lips' closing channels move
little next to the jaw, brows and smile, so a basis with 95% of the total
can keep under half of ``mouthClose`` (the demo character: 9 components,
46%) and lose the /p b m/ closures; channel c's share after k components is
sum_i<k lambda_i v_ic^2 / var_c. Animes are stored and synthesized in the
kept coefficients and mapped back to channels only when frames are emitted.

Emission. The engines' compiled kernels map coefficients back with
``basis_frames``: float32 channel frames of values @ components + mean, each
channel optionally held inside a range. Its ``summation`` picks the order of
each channel's sum, because the engines' frames are pinned to the bit: ``BLAS``
is the product numpy's ``@`` uses (``MotionBasis.reconstruct``, the anime graph
and the HMM), ``IN_ORDER`` adds the components one by one in a plain loop (the
DAM's frames); the two differ in the last bits of float64.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit
from sklearn.decomposition import PCA

from ..errors import CorpusError
from ..model_checks import ArrayReader


@dataclass(frozen=True)
class MotionBasis:
    """``mean`` (n_channels,) and orthonormal ``components`` (n_components, n_channels)."""

    mean: np.ndarray
    components: np.ndarray

    @property
    def n_components(self) -> int:
        return int(self.components.shape[0])

    def project(self, frames: np.ndarray) -> np.ndarray:
        """Channel frames (n, n_channels) to coefficients (n, n_components), float64."""
        return np.asarray((np.asarray(frames, dtype=np.float64) - self.mean) @ self.components.T)

    def reconstruct(self, coefficients: np.ndarray) -> np.ndarray:
        """Coefficients (n, n_components) back to channel frames (n, n_channels), float64."""
        frames: np.ndarray = np.asarray(coefficients, dtype=np.float64) @ self.components
        frames += self.mean
        return frames


BLAS = 0
"""``basis_frames`` summation: the BLAS product numpy's ``@`` uses."""
IN_ORDER = 1
"""``basis_frames`` summation: each channel's terms added in component order, a plain loop."""


@njit(cache=True)
def basis_frames(
    values: np.ndarray,
    components: np.ndarray,
    mean: np.ndarray,
    low: np.ndarray,
    high: np.ndarray,
    summation: int,
) -> np.ndarray:
    """Float32 channel frames (n, n_channels) of coefficients ``values`` (n, n_components):
    values @ ``components`` (n_components, n_channels) + ``mean`` (n_channels,), summed as
    ``summation`` (``BLAS`` or ``IN_ORDER``), each channel then held inside [``low``,
    ``high``] (n_channels,) in float64 before the cast; empty ``low`` and ``high``: no
    bounds. All float64."""
    n_channels = components.shape[1]
    if summation == BLAS:
        frames = np.dot(values, components)
    else:
        frames = np.zeros((values.shape[0], n_channels))
        for row in range(values.shape[0]):
            for component in range(components.shape[0]):
                weight = values[row, component]
                for channel in range(n_channels):
                    frames[row, channel] += weight * components[component, channel]
    bounded = len(low) > 0
    out = np.empty((values.shape[0], n_channels), dtype=np.float32)
    for row in range(values.shape[0]):
        for channel in range(n_channels):
            value = frames[row, channel] + mean[channel]
            if bounded:
                value = min(max(value, low[channel]), high[channel])
            out[row, channel] = value
    return out


def fit_basis(
    frames: np.ndarray, variance: float, per_channel: bool = True
) -> tuple[MotionBasis, float]:
    """PCA of ``frames`` (n, n_channels) keeping ``variance`` (0, 1] of the total variance,
    or (``per_channel``) of every moving channel's own; returns the basis and the share of
    the total variance it explains."""
    data = np.asarray(frames, dtype=np.float64)
    spread = data.var(axis=0).sum()
    if not spread > 0.0:
        raise CorpusError(
            "the training frames never change: there is no motion to learn", where="corpus"
        )
    if len(data) < 2:
        raise CorpusError("at least two training frames are needed", where="corpus")
    pca = PCA(n_components=min(data.shape), svd_solver="full").fit(data)
    kept = _components_needed(pca.explained_variance_, pca.components_, variance, per_channel)
    basis = MotionBasis(
        mean=pca.mean_.astype(np.float64), components=pca.components_[:kept].astype(np.float64)
    )
    return basis, float(np.sum(pca.explained_variance_ratio_[:kept]))


def channel_shares(eigenvalues: np.ndarray, components: np.ndarray) -> np.ndarray:
    """Share (k, n_channels) of each channel's variance explained by the first 1..k
    components, for eigenvalues (k,) and orthonormal components (k, n_channels) of a full
    PCA; channels that never move count as fully explained."""
    parts = eigenvalues[:, None] * components**2
    totals = parts.sum(axis=0)
    moving = totals > 1e-12 * max(float(totals.max()), 1e-300)
    shares = np.ones_like(parts)
    shares[:, moving] = np.cumsum(parts[:, moving], axis=0) / totals[moving]
    return np.asarray(shares)


def _components_needed(
    eigenvalues: np.ndarray, components: np.ndarray, variance: float, per_channel: bool
) -> int:
    if per_channel:
        reached = channel_shares(eigenvalues, components).min(axis=1)
    else:
        reached = np.cumsum(eigenvalues) / eigenvalues.sum()
    enough = np.flatnonzero(reached >= variance - 1e-12)
    return int(enough[0]) + 1 if len(enough) else len(eigenvalues)


def read_components(reader: ArrayReader, name: str, n_channels: int) -> np.ndarray:
    """The array ``name`` of a model: at least one orthonormal component (k, n_channels)."""
    components = np.asarray(reader.floats(name, (None, n_channels)), np.float64)
    if len(components) < 1:
        raise reader.error(name, "holds no component")
    if np.abs(components @ components.T - np.eye(len(components))).max() > 1e-4:
        raise reader.error(name, "is not orthonormal")
    return components
