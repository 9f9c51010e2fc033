"""Full-covariance Gaussian states: log-densities of every frame under every state.

Each covariance K_i is factored once, K_i = L_i L_iᵀ; with W_i = L_i⁻¹ the
log-density is −½ |W_i (x − μ_i)|² − Σ log diag L_i − (d/2) log 2π. A few frames
are whitened by every state at once with one matrix product against the stacked
W_i (d, N·d); many frames one state at a time, to bound the memory.
"""

from __future__ import annotations

import math

import numpy as np

_BATCH_VALUES = 1 << 20


class Gaussians:
    """``means`` (N, d) and symmetric positive definite ``covariances`` (N, d, d)."""

    def __init__(self, means: np.ndarray, covariances: np.ndarray) -> None:
        self.means = np.asarray(means, dtype=np.float64)
        self.covariances = np.asarray(covariances, dtype=np.float64)
        factors = np.linalg.cholesky(self.covariances)
        self.whitening = np.linalg.inv(factors)
        self.offsets = np.einsum("nij,nj->ni", self.whitening, self.means)
        count, dim = self.means.shape
        self.stacked = np.ascontiguousarray(self.whitening.reshape(count * dim, dim).T)
        self.stacked_offsets = self.offsets.reshape(-1)
        half_log_det = np.log(np.diagonal(factors, axis1=1, axis2=2)).sum(axis=1)
        self.constants = -half_log_det - 0.5 * self.means.shape[1] * math.log(2.0 * math.pi)

    @property
    def dim(self) -> int:
        return int(self.means.shape[1])

    def log_density(self, frames: np.ndarray) -> np.ndarray:
        """log N(x_t; μ_i, K_i) for frames (T, d): (T, N)."""
        x = np.asarray(frames, dtype=np.float64)
        if len(x) * self.stacked.shape[1] <= _BATCH_VALUES:  # few frames: every state at once
            z = x @ self.stacked
            z -= self.stacked_offsets
            z = z.reshape(-1, self.dim)
            squares = np.einsum("ij,ij->i", z, z).reshape(len(x), len(self.means))
            return np.asarray(-0.5 * squares + self.constants)
        out = np.empty((len(x), len(self.means)))
        for state, (whitening, offset) in enumerate(zip(self.whitening, self.offsets)):
            z = x @ whitening.T - offset
            out[:, state] = -0.5 * np.einsum("td,td->t", z, z)
        return np.asarray(out + self.constants)

    def log_determinants(self) -> np.ndarray:
        """log |K_i| (N,)."""
        return np.asarray(-2.0 * (self.constants + 0.5 * self.dim * math.log(2.0 * math.pi)))
