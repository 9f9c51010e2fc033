"""The most likely trajectory through a state sequence (Brand 1999, Eq. 5–6).

Each state i has a Gaussian over z = [y, ẏ] (pose and velocity in the motion
basis, velocity per HMM frame) with mean m_i and full covariance K_i. With y at
frames t = 0..T−1 and ẏ_t = y_t − y_{t−1}, Eq. 5 minimizes

    Σ_{t≥1} (M u_t − m_s(t))ᵀ P_s(t) (M u_t − m_s(t)) + (y_0 − μ_s(0))ᵀ Π_s(0) (y_0 − μ_s(0))

with u_t = [y_{t−1}; y_t], M = [[0, I], [−I, I]], P = K⁻¹ and Π the precision of
the pose marginal (frame 0 has no velocity). Each term adds Mᵀ P M (blocks
G_prev = E, G_cross = −(C + E) below the diagonal, G_cur = A + C + Cᵀ + E for
P = [[A, C], [Cᵀ, E]]) to a block-tridiagonal SPD system (Eq. 6): the full
precisions couple the dimensions, so one block Cholesky
(``numerics.banded.solve_spd_block_tridiagonal``) solves every dimension at once
in O(T·D³). ``numerics.banded.windowed_least_squares`` takes one
precision per window and so cannot carry the pose-velocity cross-covariance C
that Brand's states keep; the blocks are assembled here and solved there.

Frame rate: the states' velocity is the difference per HMM frame (rate R). Solved
at rate f, a frame's difference y_t − y_{t−1} spans 1 / f instead of 1 / R, so for
the same motion (locally linear over a frame) it is ρ = R / f times the learned
velocity: z_f = S z with S = diag(I, ρI). The statistics of z_f are then the mean
S m (pose mean unchanged, velocity mean × ρ) and the covariance S K S: the
pose block unchanged, the pose-velocity cross-covariance × ρ, the velocity block
× ρ². ρ < 1 above the HMM rate (the synthesis rate R_s, 120 Hz with R = 60 Hz:
ρ = 1/2), ρ = 1 at 60 fps; the pose marginal, and so Π, never changes.

A frame at a time (the causal rungs) the solve is the recursion
y_t = G_cur⁻¹ (r_cur − G_cross y_{t−1}), whose gain G_cur⁻¹ (C + E) can exceed 1
when C is large: the frames would diverge. Those rungs drop C (``coupled``
False), which leaves the gain (A + E)⁻¹ E with eigenvalues in [0, 1).

Windows: ``pins`` fix the first frames of a window to frames already committed
by a strong prior (``PIN_PRECISION`` on their pose), so pose and velocity stay
continuous across the join; those frames carry no state term.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import NamedTuple

import numpy as np
from numba import njit

from ...numerics.banded import solve_spd_block_tridiagonal

PIN_PRECISION = 1e8


class Blocks(NamedTuple):
    """The per-state terms Eq. 6's blocks are assembled from (``assemble``), D = pose
    dimensions: Π (N, D, D), Π μ (N, D), G_cur, G_prev, G_cross (N, D, D), r_cur, r_prev
    (N, D)."""

    pose_precision: np.ndarray
    pose_rhs: np.ndarray
    g_current: np.ndarray
    g_previous: np.ndarray
    g_cross: np.ndarray
    r_current: np.ndarray
    r_previous: np.ndarray


@dataclass(frozen=True)
class Dynamics:
    """Per-state terms of Eq. 5 at one synthesis rate (D = pose dimensions)."""

    pose_precision: np.ndarray  # Π (N, D, D)
    pose_rhs: np.ndarray  # Π μ (N, D)
    g_previous: np.ndarray  # (N, D, D)
    g_cross: np.ndarray  # block (t, t−1), (N, D, D)
    g_current: np.ndarray  # (N, D, D)
    r_previous: np.ndarray  # (N, D)
    r_current: np.ndarray  # (N, D)
    pose_mean: np.ndarray  # μ (N, D)
    current_inverse: np.ndarray  # G_cur⁻¹ (N, D, D)

    @property
    def dim(self) -> int:
        return int(self.pose_rhs.shape[1])

    @cached_property
    def blocks(self) -> Blocks:
        """The terms ``assemble`` reads, as one group."""
        return Blocks(
            self.pose_precision,
            self.pose_rhs,
            self.g_current,
            self.g_previous,
            self.g_cross,
            self.r_current,
            self.r_previous,
        )


def dynamics(
    means: np.ndarray, covariances: np.ndarray, ratio: float = 1.0, coupled: bool = True
) -> Dynamics:
    """The terms for states with [pose, velocity] ``means`` (N, 2D) and ``covariances``
    (N, 2D, 2D) learned at rate R, solved at R_s = R / ``ratio``. ``coupled`` False drops
    the pose-velocity cross-covariance (see ``marginal_dynamics``)."""
    dim = means.shape[1] // 2
    if not coupled:
        covariances = covariances.copy()
        covariances[:, :dim, dim:] = 0.0
        covariances[:, dim:, :dim] = 0.0
    scale = np.concatenate([np.ones(dim), np.full(dim, ratio)])
    m = means * scale
    k = covariances * scale[:, None] * scale[None, :]
    precision = np.linalg.inv(k)
    precision = 0.5 * (precision + np.swapaxes(precision, 1, 2))
    a, c, e = precision[:, :dim, :dim], precision[:, :dim, dim:], precision[:, dim:, dim:]
    mu, velocity = m[:, :dim], m[:, dim:]
    pose_precision = np.linalg.inv(k[:, :dim, :dim])
    ct = np.swapaxes(c, 1, 2)
    pm_pose = np.einsum("nij,nj->ni", a, mu) + np.einsum("nij,nj->ni", c, velocity)
    pm_velocity = np.einsum("nij,nj->ni", ct, mu) + np.einsum("nij,nj->ni", e, velocity)
    return Dynamics(
        pose_precision=pose_precision,
        pose_rhs=np.einsum("nij,nj->ni", pose_precision, mu),
        g_previous=e,
        g_cross=-(c + e),
        g_current=a + c + ct + e,
        r_previous=-pm_velocity,
        r_current=pm_pose + pm_velocity,
        pose_mean=mu,
        current_inverse=np.linalg.inv(a + c + ct + e),
    )


@njit(cache=True)
def _recurse(
    states: np.ndarray,
    previous: np.ndarray,
    started: bool,
    inverse: np.ndarray,
    cross: np.ndarray,
    rhs: np.ndarray,
    mean: np.ndarray,
) -> np.ndarray:
    out = np.empty((states.shape[0], mean.shape[1]))
    last = previous.copy()
    for t in range(states.shape[0]):
        state = states[t]
        if not started and t == 0:
            out[0] = mean[state]
        else:
            out[t] = inverse[state] @ (rhs[state] - cross[state] @ last)
        last = out[t]
    return out


def recurse(terms: Dynamics, states: np.ndarray, previous: np.ndarray | None) -> np.ndarray:
    """A frame at a time: each frame minimizes its own term of Eq. 5 given the frame before
    (``previous``, the last committed frame; None: the first frame takes its state's pose
    mean), y_t = G_cur⁻¹ (r_cur − G_cross y_{t−1}) — the limit of pinning the frame before."""
    started = previous is not None
    last = np.zeros(terms.dim) if previous is None else np.asarray(previous, dtype=np.float64)
    return np.asarray(
        _recurse(
            np.asarray(states, dtype=np.int64),
            last,
            started,
            terms.current_inverse,
            terms.g_cross,
            terms.r_current,
            terms.pose_mean,
        )
    )


def solve(terms: Dynamics, states: np.ndarray, pins: np.ndarray | None = None) -> np.ndarray:
    """The trajectory (T, D) for the state of each frame; ``pins`` (P, D) fix its first P
    frames (their states are ignored)."""
    dim = terms.dim
    held = np.zeros((0, dim)) if pins is None else np.asarray(pins, dtype=np.float64)
    diagonal, below, rhs = assemble(np.asarray(states, dtype=np.int64), held, terms.blocks)
    return solve_spd_block_tridiagonal(diagonal, below, rhs)


@njit(cache=True)
def assemble(
    states: np.ndarray, pins: np.ndarray, blocks: Blocks
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The blocks of Eq. 6 (module docstring): frame t ≥ 1 adds its state's terms to the
    blocks (t, t), (t − 1, t − 1) and (t, t − 1); pinned frames (or frame 0's pose marginal)
    instead hold their pose. Compiled; ``kernels.solve_block`` calls it too."""
    pose_precision, pose_rhs = blocks.pose_precision, blocks.pose_rhs
    g_current, g_previous, g_cross = blocks.g_current, blocks.g_previous, blocks.g_cross
    r_current, r_previous = blocks.r_current, blocks.r_previous
    frames, dim, n_pins = states.shape[0], pose_rhs.shape[1], pins.shape[0]
    diagonal = np.zeros((frames, dim, dim))
    below = np.zeros((max(frames - 1, 0), dim, dim))
    rhs = np.zeros((frames, dim))
    for t in range(min(n_pins, frames)):
        for i in range(dim):
            diagonal[t, i, i] = PIN_PRECISION
            rhs[t, i] = PIN_PRECISION * pins[t, i]
    if n_pins == 0 and frames > 0:
        diagonal[0] += pose_precision[states[0]]
        rhs[0] += pose_rhs[states[0]]
    for t in range(max(1, n_pins), frames):
        state = states[t]
        for i in range(dim):
            for j in range(dim):
                diagonal[t, i, j] += g_current[state, i, j]
                diagonal[t - 1, i, j] += g_previous[state, i, j]
                below[t - 1, i, j] += g_cross[state, i, j]
            rhs[t, i] += r_current[state, i]
            rhs[t - 1, i] += r_previous[state, i]
    return diagonal, below, rhs
