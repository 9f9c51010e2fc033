"""Linear resampling: a curve's rows read at fractional positions, by linear interpolation.

Sketch: a curve sampled evenly is read at a fractional row index p by
``bracket``: the row at or before p (low = ⌊p⌋, at most the last row), the
next row (high, the last row at the end) and the fraction f = p − low of the
way from low to high. Two rows are mixed by one of two formulas, which give
different bits for the same f, so each caller keeps the one its frames were
made with:

* ``blend_into``: low·(1 − f) + high·f, exact at both ends (f = 0 gives low,
  f = 1 gives high) and never outside them for f in [0, 1];
* ``extend_into``: low + f·(high − low), exact at low and linear in f past
  both ends, for the callers that extrapolate a curve's end segment.

Both work in float64 (rows of float32 are widened first) and store into their
output's dtype. ``sample_curves`` is the compiled ``bracket`` + ``blend_into``
over many positions of stacked curves, for callers written in numpy.
``interp_columns`` is ``np.interp`` applied to each column of a curve sampled
at arbitrary (increasing) times.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def bracket(position: float, last: int) -> tuple[int, int, float]:
    """The rows around fractional row index ``position`` (in [0, ``last``]) of a curve
    with rows 0 .. ``last``: (low, high, fraction) with low = ⌊position⌋ (at most
    ``last``), high = min(low + 1, ``last``) and fraction = position − low."""
    low = min(int(math.floor(position)), last)
    high = min(low + 1, last)
    return low, high, position - low


@njit(cache=True)
def blend_into(out: np.ndarray, rows: np.ndarray, low: int, high: int, weight: float) -> None:
    """``out`` (K,) = rows[low]·(1 − weight) + rows[high]·weight, ``rows`` (n, K), each
    element computed in float64 and stored in ``out``'s dtype."""
    for column in range(rows.shape[1]):
        out[column] = np.float64(rows[low, column]) * (1.0 - weight) + (
            np.float64(rows[high, column]) * weight
        )


@njit(cache=True)
def extend_into(out: np.ndarray, rows: np.ndarray, low: int, high: int, weight: float) -> None:
    """``out`` (K,) = rows[low] + weight·(rows[high] − rows[low]), ``rows`` (n, K), each
    element computed in float64 and stored in ``out``'s dtype: the line through the two
    rows, also for ``weight`` outside [0, 1]."""
    for column in range(rows.shape[1]):
        start = np.float64(rows[low, column])
        out[column] = start + weight * (np.float64(rows[high, column]) - start)


@njit(cache=True)
def sample_curves(values: np.ndarray, offsets: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """Stacked curves read at fractional row indices: curve c is rows
    ``offsets[c]`` .. ``offsets[c + 1]`` − 1 of ``values`` (n_rows, K), read at
    ``positions[c]`` (n_curves, m), each in [0, its row count − 1], by ``bracket`` and
    ``blend_into``: float64 (n_curves, m, K)."""
    out = np.empty((positions.shape[0], positions.shape[1], values.shape[1]))
    for curve in range(positions.shape[0]):
        first = offsets[curve]
        last = offsets[curve + 1] - first - 1
        for point in range(positions.shape[1]):
            low, high, fraction = bracket(positions[curve, point], last)
            blend_into(out[curve, point], values, first + low, first + high, fraction)
    return out


def interp_columns(times: np.ndarray, known: np.ndarray, values: np.ndarray) -> np.ndarray:
    """``np.interp(times, known, values[:, c])`` for every column c: ``values`` (n, K) at
    increasing times ``known`` (n,) read at ``times`` (m,) (same unit), held flat outside
    ``known``; float64 (m, K)."""
    out = np.empty((len(times), values.shape[1]))
    for column in range(values.shape[1]):
        out[:, column] = np.interp(times, known, values[:, column])
    return out
