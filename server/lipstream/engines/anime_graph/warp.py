"""Time warping (§6.3): map each target phoneme's time onto its anime's time.

Sketch: with audio, dynamic time warping aligns the request's MFCC frames
under the target span with the anime's MFCC frames (Euclidean frame cost,
steps (1,0), (0,1), (1,1)); each target frame maps to the mean time of the
source frames it was matched with, and the span ends map to the anime ends.
The result is a monotone piecewise-linear warp applied to the motion.
Without audio (or with under two frames on either side) the warp is linear;
the synthesizer also keeps silences linear, as they hold no speech to align.
Costs, table, backtrack and knots are compiled (numba): a phoneme's DTW is a
few thousand cells, and interpreting them cell by cell was the largest cost
of synthesis with audio.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numba import njit


@dataclass(frozen=True)
class Warp:
    """Monotone piecewise-linear map from target to source time: knots ``target`` (strictly
    increasing, s) and ``source`` (non-decreasing, s). Held flat outside the knots."""

    target: np.ndarray
    source: np.ndarray

    def __call__(self, times: np.ndarray) -> np.ndarray:
        return np.asarray(np.interp(times, self.target, self.source))


def linear_warp(start: float, end: float, source_start: float, source_end: float) -> Warp:
    return Warp(np.array([start, end]), np.array([source_start, source_end]))


@njit(cache=True, fastmath=True)
def frame_costs(target: np.ndarray, source: np.ndarray) -> np.ndarray:
    """Euclidean distance (n, m) between every target frame (n, D) and source frame (m, D)."""
    cost = np.empty((target.shape[0], source.shape[0]))
    for row in range(target.shape[0]):
        for column in range(source.shape[0]):
            total = 0.0
            for dim in range(target.shape[1]):
                difference = target[row, dim] - source[column, dim]
                total += difference * difference
            cost[row, column] = math.sqrt(total)
    return cost


@njit(cache=True)
def accumulated_costs(cost: np.ndarray) -> np.ndarray:
    """The DTW table (n, m) of a cost matrix (n, m):
    D[i, j] = cost[i, j] + min(D[i-1, j-1], D[i-1, j], D[i, j-1])."""
    rows, columns = cost.shape
    table = np.empty((rows, columns))
    table[0, 0] = cost[0, 0]
    for column in range(1, columns):
        table[0, column] = table[0, column - 1] + cost[0, column]
    for row in range(1, rows):
        table[row, 0] = table[row - 1, 0] + cost[row, 0]
        for column in range(1, columns):
            best = min(table[row - 1, column - 1], table[row - 1, column], table[row, column - 1])
            table[row, column] = cost[row, column] + best
    return table


@njit(cache=True)
def matched_means(table: np.ndarray, source_times: np.ndarray) -> np.ndarray:
    """Backtrack the optimal alignment through a DTW table (n, m) from (n-1, m-1) to (0, 0)
    (ties prefer the diagonal step, then the step from above) and return, for each row,
    the mean source time (n,) of the columns matched with it."""
    row, column = table.shape[0] - 1, table.shape[1] - 1
    totals = np.zeros(table.shape[0])
    counts = np.zeros(table.shape[0])
    while True:
        totals[row] += source_times[column]
        counts[row] += 1.0
        if row == 0 and column == 0:
            break
        if row == 0:
            column -= 1
        elif column == 0:
            row -= 1
        else:
            diagonal = table[row - 1, column - 1]
            up, left = table[row - 1, column], table[row, column - 1]
            if diagonal <= up and diagonal <= left:
                row, column = row - 1, column - 1
            elif up <= left:
                row -= 1
            else:
                column -= 1
    return totals / counts


@dataclass(frozen=True)
class Alignment:
    """One DTW problem: feature frames (n, D) at ``target_times`` (s) and (m, D) at
    ``source_times`` (s); the warp maps ``span`` (s) onto ``source_span`` (s)."""

    target_features: np.ndarray
    target_times: np.ndarray
    source_features: np.ndarray
    source_times: np.ndarray
    span: tuple[float, float]
    source_span: tuple[float, float]


def dtw_warps(problems: Sequence[Alignment]) -> list[Warp]:
    """The DTW warp of each problem.

    Each target frame maps to the mean time of the source frames the optimal path
    (Euclidean frame cost, steps (1,0), (0,1), (1,1)) matches it with; the span ends
    map to the source span's ends. Problems with under two frames on either side
    are warped linearly.
    """
    return [
        _dtw(p)
        if len(p.target_features) >= 2 and len(p.source_features) >= 2
        else linear_warp(*p.span, *p.source_span)
        for p in problems
    ]


def _dtw(problem: Alignment) -> Warp:
    table = accumulated_costs(
        frame_costs(
            np.asarray(problem.target_features, dtype=np.float64),
            np.asarray(problem.source_features, dtype=np.float64),
        )
    )
    mapped = matched_means(table, np.asarray(problem.source_times, dtype=np.float64))
    target, source = knots(
        np.asarray(problem.target_times, dtype=np.float64),
        mapped,
        *problem.span,
        *problem.source_span,
    )
    return Warp(target, source)


@njit(cache=True)
def knots(
    target_times: np.ndarray,
    mapped: np.ndarray,
    start: float,
    end: float,
    source_start: float,
    source_end: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Knots: the span's ends and each target frame strictly inside the span, mapped to
    its matched source time, clipped to the source span and made non-decreasing."""
    target = np.empty(len(target_times) + 2)
    source = np.empty(len(target_times) + 2)
    target[0], source[0] = start, source_start
    count = 1
    for index in range(len(target_times)):
        time = target_times[index]
        if start < time < end:
            target[count] = time
            source[count] = min(max(mapped[index], source[count - 1]), source_end)
            count += 1
    target[count], source[count] = end, source_end
    return target[: count + 1], source[: count + 1]


def dtw_warp(
    target_features: np.ndarray,
    target_times: np.ndarray,
    source_features: np.ndarray,
    source_times: np.ndarray,
    span: tuple[float, float],
    source_span: tuple[float, float],
) -> Warp:
    """Warp from the target ``span`` (s) onto ``source_span`` (s) by DTW of the feature frames
    (n, D) at ``target_times`` and (m, D) at ``source_times``."""
    return dtw_warps(
        [Alignment(target_features, target_times, source_features, source_times, span, source_span)]
    )[0]
