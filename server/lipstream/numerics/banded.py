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
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache

import numpy as np
import scipy.linalg
from numpy.typing import NDArray

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
