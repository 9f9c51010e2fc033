"""Banded SPD solves: windowed least squares over a sequence of frames.

Method. Several engines fit a trajectory x (T frames × D dimensions) to
per-frame targets seen through short linear windows: Brand's HMM synthesis
(Eq. 5–6 of the voice-puppetry paper; the speech-synthesis "parameter
generation" of HTS), boundary smoothing in the expressive DP (Deng & Neumann
Eq. 16), one-sided filters. Each window w is a short odd-length stencil
c_w (``[1.0]`` for position, ``[-0.5, 0, 0.5]`` for velocity, ``[1, -2, 1]``
for curvature), so (W_w x)_t = Σ_k c_w[k] · x_{t+k-h_w}. The solve minimises

    Σ_w Σ_t (W_w x − μ_{w,t})ᵀ P_{w,t} (W_w x − μ_{w,t})

whose normal equations (Σ_w W_wᵀ P_w W_w) x = Σ_w W_wᵀ P_w μ_w are symmetric
positive definite and banded: frame t couples only with frames within twice
the widest window's half-width. Full D×D precisions couple the dimensions, so
the unknowns are ordered time-major (index t·D + d) and the band is
(2h + 1)·D − 1 wide; the banded Cholesky then costs O(T·h²·D³), never a dense
T×T solve. Diagonal precisions decouple the dimensions: each gets its own
band of width 2h, solved together as one dimension-major system.

A window term at frame t is used only where the stencil lies inside the
sequence; near the ends a velocity or curvature target simply has no term.

A system solved again and again with new right-hand sides (the expressive DP's
boundary smoothing: one matrix per pattern of weights) is factored once by
``factor_spd_banded`` (LAPACK's dpbtrf) and solved by ``solve_with_factor``
(dpbtrs): ``solve_spd_banded`` is LAPACK's dpbsv, which is those two calls, so
the solutions are the same to the bit, except for a tridiagonal A (one
sub-diagonal), which scipy's ``solveh_banded`` solves by dptsv (LDLᵀ) instead.

Block-tridiagonal systems (first-order windows with full precisions, as Brand's
Eq. 6) have a sharper solver than LAPACK's band storage, whose 2D − 1
sub-diagonals carry a quarter zeros and cost about 2D³ multiply-adds per frame
to factor: ``solve_spd_block_tridiagonal`` factors A = L Lᵀ a frame at a time
(block Cholesky, the Riccati recursion of a Kalman smoother): with
C_t = B_{t−1} L_{t−1}⁻ᵀ for the block B_{t−1} = A[t, t−1],
L_t L_tᵀ = A[t, t] − C_t C_tᵀ, then one forward and one backward substitution;
about 7/6 D³ multiply-adds per frame, in one compiled loop.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import scipy.linalg
from numba import njit
from numpy.typing import NDArray
from scipy.linalg.lapack import dpbtrf, dpbtrs

FloatArray = NDArray[np.float64]


def solve_spd_banded(lower_bands: FloatArray, rhs: FloatArray) -> FloatArray:
    """Solve A x = rhs for a symmetric positive definite banded A.

    ``lower_bands`` has shape (bandwidth + 1, N) in LAPACK's lower storage:
    ``lower_bands[i - j, j] = A[i, j]`` for i ≥ j. ``rhs`` is (N,) or (N, K).
    Raises ``numpy.linalg.LinAlgError`` when A is not positive definite.
    """
    if lower_bands.ndim != 2 or lower_bands.shape[1] != rhs.shape[0]:
        raise ValueError(
            f"banded matrix of shape {lower_bands.shape} does not match a right-hand "
            f"side of {rhs.shape[0]} rows"
        )
    if not (np.isfinite(lower_bands).all() and np.isfinite(rhs).all()):
        raise ValueError("banded system has a non-finite entry")
    try:
        solution = scipy.linalg.solveh_banded(lower_bands, rhs, lower=True, check_finite=False)
    except np.linalg.LinAlgError as error:
        raise np.linalg.LinAlgError(
            "banded system is not positive definite: some frame has no positive precision "
            f"from any window ({error})"
        ) from error
    return np.asarray(solution, dtype=np.float64)


@dataclass(frozen=True)
class BandedFactor:
    """The banded Cholesky factor L (A = L Lᵀ) of ``factor_spd_banded``, read-only, in
    LAPACK's lower band storage (``lower[i - j, j] = L[i, j]``)."""

    lower: FloatArray


def factor_spd_banded(lower_bands: FloatArray) -> BandedFactor | None:
    """Factor the symmetric positive definite banded A of ``lower_bands`` (as
    ``solve_spd_banded`` reads it) once, for ``solve_with_factor``; None when A has a
    non-finite entry or is not positive definite (``solve_spd_banded`` says which)."""
    if lower_bands.ndim != 2:
        raise ValueError(f"banded matrix must be (bandwidth + 1, N), got {lower_bands.shape}")
    if not np.isfinite(lower_bands).all():
        return None
    factor, info = dpbtrf(lower_bands, lower=1)
    if info != 0:
        return None
    lower = np.asarray(factor, dtype=np.float64)
    lower.setflags(write=False)
    return BandedFactor(lower)


def solve_with_factor(factor: BandedFactor, rhs: FloatArray) -> FloatArray:
    """Solve A x = rhs, (N,) or (N, K), with A's ``factor``: ``solve_spd_banded``'s solution
    to the bit (but for a tridiagonal A, see above). Raises ``ValueError`` when rhs does not
    match A or has a non-finite entry."""
    if factor.lower.shape[1] != rhs.shape[0]:
        raise ValueError(
            f"banded factor of shape {factor.lower.shape} does not match a right-hand side of "
            f"{rhs.shape[0]} rows"
        )
    if not np.isfinite(rhs).all():
        raise ValueError("banded system has a non-finite entry")
    solution, info = dpbtrs(factor.lower, rhs, lower=1)
    if info != 0:
        raise ValueError(f"dpbtrs refused its argument {-info}")
    return np.asarray(solution, dtype=np.float64)


def solve_spd_block_tridiagonal(
    diagonal: FloatArray, below: FloatArray, rhs: FloatArray
) -> FloatArray:
    """Solve A x = rhs for a symmetric positive definite block-tridiagonal A.

    ``diagonal`` (T, D, D) holds the blocks A[t, t] (only their lower triangles are read),
    ``below`` (T − 1, D, D) the blocks A[t + 1, t], ``rhs`` (T, D); returns x (T, D).
    Raises ``numpy.linalg.LinAlgError`` when A is not positive definite.
    """
    frames = diagonal.shape[0] if diagonal.ndim == 3 else -1
    if (
        frames < 1
        or diagonal.shape[1] != diagonal.shape[2]
        or below.shape != (frames - 1, *diagonal.shape[1:])
        or rhs.shape != diagonal.shape[:2]
    ):
        raise ValueError(
            f"block-tridiagonal system of diagonal {diagonal.shape}, below {below.shape} and "
            f"right-hand side {rhs.shape} does not fit (T, D, D), (T − 1, D, D), (T, D)"
        )
    blocks, coupling, right = (
        np.ascontiguousarray(a, dtype=np.float64) for a in (diagonal, below, rhs)
    )
    solution = np.empty(rhs.shape)
    check_block_tridiagonal(solve_block_tridiagonal_into(blocks, coupling, right, solution))
    return solution


SOLVED = -1
NOT_FINITE = -2


@njit(cache=True)
def solve_block_tridiagonal_into(
    diagonal: FloatArray, below: FloatArray, rhs: FloatArray, out: FloatArray
) -> int:
    """``solve_spd_block_tridiagonal`` for compiled callers, on C-contiguous arrays of the
    shapes it checks: writes x into ``out`` and returns ``SOLVED``, ``NOT_FINITE``, or the
    first frame whose Schur complement is not positive definite (``check_block_tridiagonal``
    raises the matching error)."""
    for values in (diagonal.reshape(-1), below.reshape(-1), rhs.reshape(-1)):
        if not _all_finite(values):
            return NOT_FINITE
    return _block_cholesky_solve(diagonal, below, rhs, out)


def check_block_tridiagonal(code: int) -> None:
    """Raise the error that a ``solve_block_tridiagonal_into`` result ``code`` stands for."""
    if code == NOT_FINITE:
        raise ValueError("block-tridiagonal system has a non-finite entry")
    if code >= 0:
        raise np.linalg.LinAlgError(
            f"block-tridiagonal system is not positive definite (at frame {code})"
        )


@njit(cache=True)
def _all_finite(values: FloatArray) -> bool:
    for value in values:
        if not np.isfinite(value):
            return False
    return True


@njit(cache=True, fastmath={"reassoc", "contract"})  # vectorised sums; NaN checks still hold
def _block_cholesky_solve(
    diagonal: FloatArray, below: FloatArray, rhs: FloatArray, out: FloatArray
) -> int:
    """The factorization and substitutions of ``solve_spd_block_tridiagonal`` into ``out``;
    returns −1, or the first frame whose Schur complement is not positive definite."""
    frames, dims = rhs.shape
    factor = np.zeros((frames, dims, dims))  # L_t, lower triangular
    coupling = np.zeros((frames, dims, dims))  # C_t = B_{t-1} L_{t-1}^-T (C_0 unused)
    forward = np.empty((frames, dims))
    schur = np.empty((dims, dims))
    for t in range(frames):
        schur[:, :] = diagonal[t]
        if t > 0:
            previous, block, c = factor[t - 1], below[t - 1], coupling[t]
            # C_t L_{t-1}^T = B_{t-1}, column by column: the rows are independent, so their
            # divisions overlap rather than wait on each other along a row.
            for j in range(dims):
                for i in range(dims):
                    value = block[i, j]
                    for k in range(j):
                        value -= c[i, k] * previous[j, k]
                    c[i, j] = value / previous[j, j]
            for i in range(dims):
                for j in range(i + 1):
                    value = 0.0
                    for k in range(dims):
                        value += c[i, k] * c[j, k]
                    schur[i, j] -= value
        lower = factor[t]
        for j in range(dims):
            value = schur[j, j]
            for k in range(j):
                value -= lower[j, k] * lower[j, k]
            if not value > 0.0:
                return t
            pivot = np.sqrt(value)
            lower[j, j] = pivot
            for i in range(j + 1, dims):
                value = schur[i, j]
                for k in range(j):
                    value -= lower[i, k] * lower[j, k]
                lower[i, j] = value / pivot
        for i in range(dims):  # L_t y_t = r_t − C_t y_{t-1}
            value = rhs[t, i]
            if t > 0:
                for k in range(dims):
                    value -= coupling[t, i, k] * forward[t - 1, k]
            for k in range(i):
                value -= lower[i, k] * forward[t, k]
            forward[t, i] = value / lower[i, i]
    for t in range(frames - 1, -1, -1):  # L_tᵀ x_t = y_t − C_{t+1}ᵀ x_{t+1}
        lower = factor[t]
        for i in range(dims - 1, -1, -1):
            value = forward[t, i]
            if t < frames - 1:
                for k in range(dims):
                    value -= coupling[t + 1, k, i] * out[t + 1, k]
            for k in range(i + 1, dims):
                value -= lower[k, i] * out[t, k]
            out[t, i] = value / lower[i, i]
    return -1


def windowed_least_squares(
    windows: Sequence[NDArray[np.floating]],
    means: NDArray[np.floating],
    precisions: NDArray[np.floating],
) -> FloatArray:
    """The trajectory x of shape (T, D) minimising the windowed quadratic above.

    ``windows``: W stencils, each 1-D with odd length. ``means``: (W, T, D)
    targets. ``precisions``: (W, T, D, D) symmetric positive semi-definite
    matrices, or (W, T, D) diagonals. Units are the caller's: a velocity
    window in frames means velocity targets per frame.
    """
    stencils = [_checked_stencil(window) for window in windows]
    means64 = np.asarray(means, dtype=np.float64)
    precisions64 = np.asarray(precisions, dtype=np.float64)
    _check_shapes(len(stencils), means64, precisions64)
    half = max(len(stencil) // 2 for stencil in stencils)
    if precisions64.ndim == 3:
        return _solve_diagonal(stencils, means64, precisions64, half)
    return _solve_full(stencils, means64, precisions64, half)


def _checked_stencil(window: NDArray[np.floating]) -> FloatArray:
    stencil = np.asarray(window, dtype=np.float64)
    if stencil.ndim != 1 or len(stencil) % 2 != 1:
        raise ValueError(f"a window must be 1-D with odd length, got shape {stencil.shape}")
    return stencil


def _check_shapes(count: int, means: FloatArray, precisions: FloatArray) -> None:
    if means.ndim != 3 or means.shape[0] != count:
        raise ValueError(f"means must be (W={count}, T, D), got {means.shape}")
    if precisions.shape[:3] != means.shape or precisions.ndim not in (3, 4):
        raise ValueError(
            f"precisions must be (W, T, D) or (W, T, D, D) matching means {means.shape}, "
            f"got {precisions.shape}"
        )
    if precisions.ndim == 4 and precisions.shape[3] != means.shape[2]:
        raise ValueError(f"full precisions must be D×D, got {precisions.shape}")


def _valid_frames(stencil_length: int, frames: int) -> slice:
    """Frames t whose stencil lies wholly inside the sequence."""
    half = stencil_length // 2
    return slice(half, max(half, frames - half))


def _solve_full(
    stencils: list[FloatArray], means: FloatArray, precisions: FloatArray, half: int
) -> FloatArray:
    _, frames, dims, _ = precisions.shape
    blocks = np.zeros((2 * half + 1, frames, dims, dims))
    rhs = np.zeros((frames, dims))
    for stencil, mean, precision in zip(stencils, means, precisions, strict=True):
        _accumulate_full(stencil, mean, precision, blocks, rhs)
    rows, cols, offsets, starts, a_index, b_index = _full_band_layout(frames, dims, half)
    bands = np.zeros(((2 * half + 1) * dims, frames * dims))
    bands[rows, cols] = blocks[offsets, starts, a_index, b_index]
    return solve_spd_banded(bands, rhs.reshape(-1)).reshape(frames, dims)


def _accumulate_full(
    stencil: FloatArray,
    mean: FloatArray,
    precision: FloatArray,
    blocks: FloatArray,
    rhs: FloatArray,
) -> None:
    """Add Wᵀ P W into the lower block bands and Wᵀ P μ into the right-hand side.

    ``blocks[m, t]`` is the block A[t + m, t].
    """
    frames = mean.shape[0]
    valid = _valid_frames(len(stencil), frames)
    centres = np.arange(frames)[valid]
    if len(centres) == 0:
        return
    weighted_mean = np.einsum("tij,tj->ti", precision[valid], mean[valid])
    shift = len(stencil) // 2
    for k1, c1 in enumerate(stencil):
        if c1 == 0.0:
            continue
        rhs[centres + k1 - shift] += c1 * weighted_mean
        for k2, c2 in enumerate(stencil[: k1 + 1]):
            if c2 != 0.0:
                blocks[k1 - k2, centres + k2 - shift] += c1 * c2 * precision[valid]


@lru_cache(maxsize=64)
def _full_band_layout(frames: int, dims: int, half: int) -> tuple[NDArray[np.intp], ...]:
    """Where each lower block entry A[(t+m)·D + a, t·D + b] lands in LAPACK storage."""
    offsets, starts, a_index, b_index = np.meshgrid(
        np.arange(2 * half + 1),
        np.arange(frames),
        np.arange(dims),
        np.arange(dims),
        indexing="ij",
    )
    diagonal = offsets * dims + a_index - b_index
    keep = (diagonal >= 0) & (starts + offsets < frames)
    columns = starts * dims + b_index
    return (
        diagonal[keep],
        columns[keep],
        offsets[keep],
        starts[keep],
        a_index[keep],
        b_index[keep],
    )


def _solve_diagonal(
    stencils: list[FloatArray], means: FloatArray, precisions: FloatArray, half: int
) -> FloatArray:
    _, frames, dims = precisions.shape
    bands = np.zeros((2 * half + 1, dims, frames))
    rhs = np.zeros((dims, frames))
    for stencil, mean, precision in zip(stencils, means, precisions, strict=True):
        _accumulate_diagonal(stencil, mean.T, precision.T, bands, rhs)
    for offset in range(1, 2 * half + 1):
        bands[offset, :, frames - offset :] = 0.0
    solution = solve_spd_banded(bands.reshape(2 * half + 1, -1), rhs.reshape(-1))
    return solution.reshape(dims, frames).T


def _accumulate_diagonal(
    stencil: FloatArray,
    mean: FloatArray,
    precision: FloatArray,
    bands: FloatArray,
    rhs: FloatArray,
) -> None:
    """As ``_accumulate_full`` for (D, T) diagonal precisions: ``bands[m, d, t]`` = A_d[t+m, t]."""
    frames = mean.shape[1]
    valid = _valid_frames(len(stencil), frames)
    centres = np.arange(frames)[valid]
    if len(centres) == 0:
        return
    weight = precision[:, valid]
    weighted_mean = weight * mean[:, valid]
    shift = len(stencil) // 2
    for k1, c1 in enumerate(stencil):
        if c1 == 0.0:
            continue
        rhs[:, centres + k1 - shift] += c1 * weighted_mean
        for k2, c2 in enumerate(stencil[: k1 + 1]):
            if c2 != 0.0:
                bands[k1 - k2][:, centres + k2 - shift] += c1 * c2 * weight
