"""EM-style training of the DAMs (Lin et al., Eq. 5-9).

Every occurrence j of a mode contributes D(t_j; sigma_mode) * A_mode(t_j) to the
frames of its utterance within its dominance reach (Eq. 2). One sigma per mode
is shared by the channels; each channel has its own polynomial coefficients.

- E-step (Eq. 5-7): with sigma fixed the coefficients are linear. The design
  matrix has one row per frame and, for mode k, the columns D(t_j)·t_j^m
  (m = 0..M); occurrences of the same mode add into the same columns. It is
  built sparse (scipy.sparse, frames x modes·(M+1)) and the normal equations
  (DᵀD + ridge·I) A = DᵀC, a small sparse system, are solved for every channel
  at once. Nothing frames x frames is ever formed.
- M-step (Eq. 8-9): with A fixed, one Gauss-Newton step on every sigma:
  (JᵀJ) δ = Jᵀf over the residuals f of every frame and channel, followed by
  backtracking (halving δ) until the objective does not increase; if no halving
  helps, sigma stays.
- ``ConvergenceMonitor`` records the objective (squared error plus the ridge
  term the E-step minimizes) after each iteration, checks it never increases
  and stops when the relative improvement falls below ``tol``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .dominance import dominance, dominance_dsigma, powers, reach
from .modes import Occurrences

SIGMA_MIN = 0.02
DENSE_COLUMNS = 4000


@dataclass(frozen=True)
class Settings:
    """Training constants: polynomial ``degree`` M, dominance ``eps``, dominance cut-off
    ``tol``, ``ridge`` on the coefficients, the largest ``sigma_max`` a sigma may take."""

    degree: int
    eps: float
    tol: float
    ridge: float
    sigma_max: float = 2.0


@dataclass(frozen=True)
class Pairs:
    """(frame row, occurrence) pairs within each occurrence's dominance reach, with local time."""

    row: np.ndarray
    occurrence: np.ndarray
    local: np.ndarray


class NonMonotoneError(AssertionError):
    """The EM objective increased: a bug, since both steps are built not to raise it."""


@dataclass
class ConvergenceMonitor:
    """History of the EM objective (hmmlearn's ConvergenceMonitor, checked monotone)."""

    tol: float
    n_iter: int
    history: list[float] = field(default_factory=list)

    def report(self, objective: float) -> None:
        if self.history and objective > self.history[-1] * (1.0 + 1e-9) + 1e-12:
            raise NonMonotoneError(f"EM objective rose from {self.history[-1]!r} to {objective!r}")
        self.history.append(objective)

    @property
    def converged(self) -> bool:
        if len(self.history) >= self.n_iter + 1:
            return True
        if len(self.history) < 2:
            return False
        previous, current = self.history[-2], self.history[-1]
        return previous - current <= self.tol * max(previous, 1e-300)


def pairs(occurrences: Occurrences, sigma: np.ndarray, mode: np.ndarray, s: Settings) -> Pairs:
    """Every frame within each occurrence's reach (D >= tol), vectorised over occurrences."""
    fps = occurrences.fps
    span = reach(sigma[mode], s.eps, s.tol)
    start, duration = occurrences.start, occurrences.duration
    low = np.maximum(np.ceil((start - span * duration) * fps - 1e-9), 0).astype(np.int64)
    high = np.minimum(
        np.floor((start + duration * (1.0 + span)) * fps + 1e-9).astype(np.int64) + 1,
        occurrences.rows,
    )
    lengths = np.maximum(high - low, 0)
    occurrence = np.repeat(np.arange(len(start)), lengths)
    within = np.arange(int(lengths.sum())) - np.repeat(np.cumsum(lengths) - lengths, lengths)
    frame = low[occurrence] + within
    local = (frame / fps - start[occurrence]) / duration[occurrence]
    return Pairs(occurrences.first_row[occurrence] + frame, occurrence, local)


def design(
    occurrences: Occurrences, mode: np.ndarray, sigma: np.ndarray, n_rows: int, s: Settings
) -> sp.csr_matrix:
    """The sparse design matrix of Eq. 6-7: rows frames, columns mode·(M+1) + m."""
    found = pairs(occurrences, sigma, mode, s)
    modes_of_pairs = mode[found.occurrence]
    weight = dominance(found.local, sigma[modes_of_pairs], s.eps)
    width = s.degree + 1
    values = weight[:, None] * powers(found.local, s.degree)
    columns = modes_of_pairs[:, None] * width + np.arange(width)
    rows = np.repeat(found.row, width)
    shape = (n_rows, len(sigma) * width)
    return sp.csr_matrix((values.ravel(), (rows, columns.ravel())), shape=shape)


def e_step(matrix: sp.csr_matrix, frames: np.ndarray, ridge: float) -> np.ndarray:
    """The coefficients (columns x channels) solving (DᵀD + ridge·I) A = DᵀC (Eq. 5)."""
    gram = (matrix.T @ matrix).tocsc() + ridge * sp.identity(matrix.shape[1], format="csc")
    return solve_gram(gram, np.asarray(matrix.T @ frames))


def solve_gram(gram: sp.csc_matrix, right: np.ndarray) -> np.ndarray:
    """Solve a normal-equation system (columns x columns, never frames x frames): dense
    when small enough to be faster so, else sparse LU. Not banded: modes that meet in an
    utterance couple whatever their indices (the demo DAM: bandwidth 779 of 800 columns)."""
    if gram.shape[0] <= DENSE_COLUMNS:
        return np.asarray(scipy.linalg.solve(gram.toarray(), right, assume_a="sym"))
    return np.asarray(spla.splu(gram).solve(right))


def objective(
    matrix: sp.csr_matrix, coefficients: np.ndarray, frames: np.ndarray, ridge: float
) -> float:
    """Squared error of the fit plus the ridge term: what both steps decrease."""
    residual = frames - matrix @ coefficients
    return float(np.sum(residual * residual) + ridge * np.sum(coefficients * coefficients))


def m_step(
    occurrences: Occurrences,
    mode: np.ndarray,
    sigma: np.ndarray,
    coefficients: np.ndarray,
    frames: np.ndarray,
    s: Settings,
    current: float,
) -> tuple[np.ndarray, float]:
    """One Gauss-Newton step on every sigma (Eq. 8-9) with backtracking; the new sigma and
    its objective, never above ``current``."""
    found = pairs(occurrences, sigma, mode, s)
    n_rows, n_channels = frames.shape
    modes_of_pairs = mode[found.occurrence]
    width = s.degree + 1
    animeme = np.einsum(
        "pm,pmc->pc",
        powers(found.local, s.degree),
        coefficients.reshape(len(sigma), width, n_channels)[modes_of_pairs],
    )
    slope = dominance_dsigma(found.local, sigma[modes_of_pairs], s.eps)[:, None] * animeme
    matrix = design(occurrences, mode, sigma, n_rows, s)
    residual = frames - matrix @ coefficients
    # J has one row per (frame, channel) and one column per mode.
    rows = (found.row[:, None] * n_channels + np.arange(n_channels)).ravel()
    columns = np.repeat(modes_of_pairs, n_channels)
    jacobian = sp.csr_matrix(
        (slope.ravel(), (rows, columns)), shape=(n_rows * n_channels, len(sigma))
    )
    gram = (jacobian.T @ jacobian).tocsc()
    gram = gram + 1e-12 * sp.identity(len(sigma), format="csc")
    step = solve_gram(gram, np.asarray(jacobian.T @ residual.ravel()))
    for halving in range(12):
        trial = np.clip(sigma + step / 2.0**halving, SIGMA_MIN, s.sigma_max)
        value = objective(
            design(occurrences, mode, trial, n_rows, s), coefficients, frames, s.ridge
        )
        if value <= current:
            return trial, value
    return sigma, current


@dataclass(frozen=True)
class Fit:
    """The fitted ``sigma`` (modes,), ``coefficients`` (modes, M+1, channels), and the
    monitor's objective history."""

    sigma: np.ndarray
    coefficients: np.ndarray
    history: list[float]


def fit(
    occurrences: Occurrences,
    mode: np.ndarray,
    n_modes: int,
    frames: np.ndarray,
    s: Settings,
    n_iter: int,
    tol: float,
    sigma_init: float = 1.0,
) -> Fit:
    """The EM loop from sigma = ``sigma_init``: E-step, then (M-step, E-step) until the
    monitor converges."""
    sigma = np.full(n_modes, sigma_init)
    monitor = ConvergenceMonitor(tol=tol, n_iter=n_iter)
    matrix = design(occurrences, mode, sigma, len(frames), s)
    coefficients = e_step(matrix, frames, s.ridge)
    monitor.report(objective(matrix, coefficients, frames, s.ridge))
    while not monitor.converged:
        sigma, value = m_step(
            occurrences, mode, sigma, coefficients, frames, s, monitor.history[-1]
        )
        matrix = design(occurrences, mode, sigma, len(frames), s)
        coefficients = e_step(matrix, frames, s.ridge)
        monitor.report(objective(matrix, coefficients, frames, s.ridge))
    shaped = coefficients.reshape(n_modes, s.degree + 1, frames.shape[1])
    return Fit(sigma, shaped, monitor.history)
