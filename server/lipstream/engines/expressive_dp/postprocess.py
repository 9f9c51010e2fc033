"""Post-processing (§VII-B): time warping, boundary smoothing (Eq. 16), silence, resampling.

Method. Frames are made on a grid at the model's recording rate R (120 Hz for
the demo character, the paper's rate) and sampled at the requested times by
linear interpolation, so every output rate reads the same motion. Span k owns
the grid points g with start_k ≤ g/R < end_k (the point at the very end of the
input belongs to the last span, at relative time 1).

* Time warping: a non-silence span shows its node resampled linearly over the
  span's relative time (``nodes.warp_node``, compiled for a span's grid points in
  ``warped_points``), whatever the node's own length.
* Smoothing (Eq. 16): at a join of two non-silence spans whose nodes are not
  captured neighbours (pre(o_{k+1}) ≠ o_k), the last s points of span k and the
  first s of span k + 1 (s = ``half``; fewer when a span is short: a span gives
  at most half its points to the join before it, and the rest to the join
  after, so joins never overlap) are refitted as g minimising
  Σ W_j (g − f)² + Σ W_k (g − f)² + λ Σ (Δ²g)², W the visibility weight of each
  side's node phoneme (Table IV: 2 for /p b m f v w/, 0.5 for /k g ch ng r/, 1
  otherwise), λ = ``smoothness``. It is one banded solve per join for every
  basis component at once, the Cholesky factor kept per weight pattern and only
  its substitutions run (``smooth_join``, ``numerics.banded.factor_spd_banded`` and
  ``solve_with_factor``: what ``solve_spd_banded`` gives, bit for bit).
* Silence: a silence has no node (the search splits there, ``search``); its
  points are interpolated linearly from the last frame of the node before it
  (the last of one search segment) to the first frame of the node after it (the
  first of the next), the one side that exists at the ends of the input, the
  rest pose when neither does. Adjacent silences are drawn as one line.

A span's points depend on the nodes of spans k − 1, k and k + 1 only (of the
spans around a run of silences, which the synthesizer merges into one span).
"""

from __future__ import annotations

import math
from bisect import bisect_right
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from operator import attrgetter

import numpy as np
from numba import njit

from ...numerics.banded import (
    BandedFactor,
    factor_spd_banded,
    solve_spd_banded,
    solve_with_factor,
)
from ...numerics.resample import blend_into, bracket, extend_into
from ...phonemes import SILENCE
from ...timeline import PhonemeSpan
from .nodes import NodeDatabase

VISIBILITY = {"P": 2.0, "B": 2.0, "M": 2.0, "F": 2.0, "V": 2.0, "W": 2.0} | {
    "K": 0.5,
    "G": 0.5,
    "CH": 0.5,
    "NG": 0.5,
    "R": 0.5,
}
CURVATURE = np.array([1.0, -2.0, 1.0])
_EPS = 1e-9
_end = attrgetter("end")


def owned(span: PhonemeSpan, rate: float) -> tuple[int, int]:
    """The grid points [low, high) span ``span`` owns."""
    return math.ceil(span.start * rate - _EPS), math.ceil(span.end * rate - _EPS)


def visibility(phoneme: str) -> float:
    return VISIBILITY.get(phoneme, 1.0)


@dataclass
class RenderCache:
    """A stream's made span points (``points``), unsmoothed points (``bases``) and solved
    joins (``joins``, of spans k and k + 1), by span index."""

    points: dict[int, np.ndarray] = field(default_factory=dict)
    bases: dict[int, np.ndarray] = field(default_factory=dict)
    joins: dict[int, np.ndarray] = field(default_factory=dict)

    def forget_before(self, first: int) -> None:
        for kept in (self.points, self.bases, self.joins):
            for k in [k for k in kept if k < first]:
                del kept[k]


class Renderer:
    """Grid values and output frames of a node path over contiguous spans."""

    def __init__(
        self, nodes: NodeDatabase, rest: np.ndarray, rate: float, half: int, smoothness: float
    ) -> None:
        self.nodes = nodes
        self.rest = rest
        self.rate = rate
        self.half = half
        self.smoothness = smoothness

    def _base(self, spans: Sequence[PhonemeSpan], path: Sequence[int], k: int) -> np.ndarray:
        """Span k's points before smoothing."""
        span = spans[k]
        low, high = owned(span, self.rate)
        if span.phoneme != SILENCE:
            nodes = self.nodes
            return warped_points(
                nodes.frames,
                nodes.offsets,
                int(path[k]),
                low,
                high,
                self.rate,
                span.start,
                span.end,
            )
        return self._silence(spans, path, k, np.arange(low, high) / self.rate)

    def _silence(
        self, spans: Sequence[PhonemeSpan], path: Sequence[int], k: int, times: np.ndarray
    ) -> np.ndarray:
        """The line over the run of silences holding span k, at ``times``."""
        first, last = k, k
        while first > 0 and spans[first - 1].phoneme == SILENCE:
            first -= 1
        while last + 1 < len(spans) and spans[last + 1].phoneme == SILENCE:
            last += 1
        left = self.nodes.node_frames(int(path[first - 1]))[-1] if first > 0 else None
        right = self.nodes.node_frames(int(path[last + 1]))[0] if last + 1 < len(spans) else None
        if left is None:
            left = self.rest if right is None else right
        if right is None:
            right = left
        start, end = spans[first].start, spans[last].end
        relative = np.clip((times - start) / (end - start), 0.0, 1.0)
        return np.asarray(left + relative[:, None] * (right - left))

    def _smoothed(self, spans: Sequence[PhonemeSpan], path: Sequence[int], k: int) -> bool:
        """Whether the join of spans k and k + 1 is smoothed."""
        if spans[k].phoneme == SILENCE or spans[k + 1].phoneme == SILENCE:
            return False
        return int(self.nodes.pre[int(path[k + 1])]) != int(path[k])

    def _kept_base(
        self, spans: Sequence[PhonemeSpan], path: Sequence[int], k: int, kept: RenderCache | None
    ) -> np.ndarray:
        """``_base``, read from or left in ``kept`` (not to be written)."""
        if kept is None:
            return self._base(spans, path, k)
        base = kept.bases.get(k)
        if base is None:
            base = kept.bases[k] = self._base(spans, path, k)
        return base

    def _kept_join(
        self,
        spans: Sequence[PhonemeSpan],
        path: Sequence[int],
        k: int,
        left: np.ndarray,
        right: np.ndarray,
        kept: RenderCache | None,
    ) -> np.ndarray:
        """``_join`` of spans k and k + 1, read from or left in ``kept``: both spans' points
        read it, with the same ``left`` and ``right``."""
        if kept is None:
            return self._join(spans, path, k, left, right)
        solved = kept.joins.get(k)
        if solved is None:
            solved = kept.joins[k] = self._join(spans, path, k, left, right)
        return solved

    def span_values(
        self,
        spans: Sequence[PhonemeSpan],
        path: Sequence[int],
        k: int,
        kept: RenderCache | None = None,
    ) -> np.ndarray:
        """Span k's points, smoothed at its joins (needs the nodes of k − 1 .. k + 1); ``kept``
        (a stream's) holds the unsmoothed points and joins already made."""
        values = self._kept_base(spans, path, k, kept).copy()
        count = len(values)
        head = min(self.half, count // 2)
        tail = min(self.half, count - head)
        if k > 0 and head and self._smoothed(spans, path, k - 1):
            before = self._kept_base(spans, path, k - 1, kept)
            before_head = min(self.half, len(before) // 2)
            before_tail = min(self.half, len(before) - before_head)
            if before_tail:
                solved = self._kept_join(
                    spans, path, k - 1, before[-before_tail:], values[:head], kept
                )
                values[:head] = solved[before_tail:]
        if k + 1 < len(spans) and tail and self._smoothed(spans, path, k):
            after = self._kept_base(spans, path, k + 1, kept)
            after_head = min(self.half, len(after) // 2)
            if after_head:
                solved = self._kept_join(spans, path, k, values[-tail:], after[:after_head], kept)
                values[-tail:] = solved[:tail]
        return values

    def _join(
        self,
        spans: Sequence[PhonemeSpan],
        path: Sequence[int],
        k: int,
        left: np.ndarray,
        right: np.ndarray,
    ) -> np.ndarray:
        """Eq. 16 over the points ``left`` (end of span k) and ``right`` (start of k + 1)."""
        fitted = np.concatenate([left, right])
        weights = np.concatenate(
            [
                np.full(len(left), visibility(spans[k].phoneme)),
                np.full(len(right), visibility(spans[k + 1].phoneme)),
            ]
        )
        if len(fitted) < 3:
            return fitted
        return smooth_join(fitted, weights, self.smoothness)

    def terminal(self, spans: Sequence[PhonemeSpan], path: Sequence[int]) -> np.ndarray:
        """The point at the end of the last span (relative time 1)."""
        k = len(spans) - 1
        if spans[k].phoneme != SILENCE:
            return np.asarray(self.nodes.node_frames(int(path[k]))[-1])
        return np.asarray(self._silence(spans, path, k, np.array([spans[k].end]))[0])

    def grid(
        self,
        spans: Sequence[PhonemeSpan],
        path: Sequence[int],
        low: int,
        high: int,
        kept: RenderCache | None = None,
    ) -> np.ndarray:
        """Grid points low..high (inclusive), (high − low + 1, K). ``kept`` (a stream's) holds
        what spans already made, by index, and takes what is made now: a span's points are
        final once made (its frames waited for the nodes they read)."""
        out = np.empty((high - low + 1, self.nodes.frames.shape[1]))
        filled = np.zeros(high - low + 1, dtype=bool)
        first = max(0, _span_at(spans, low / self.rate) - 1)
        if kept is not None:  # a stream's times ascend: no later call reads spans before these
            kept.forget_before(first - 1)
        for k in range(first, len(spans)):
            start, stop = owned(spans[k], self.rate)
            if start > high:
                break
            if stop <= low or stop <= start:
                continue
            values = kept.points.get(k) if kept is not None else None
            if values is None:
                values = self.span_values(spans, path, k, kept)
                if kept is not None:
                    kept.points[k] = values
            a, b = max(start, low), min(stop, high + 1)
            out[a - low : b - low] = values[a - start : b - start]
            filled[a - low : b - low] = True
        if not filled.all():
            out[~filled] = self.terminal(spans, path)
        return out

    def frames(
        self,
        spans: Sequence[PhonemeSpan],
        path: Sequence[int],
        times: np.ndarray,
        kept: RenderCache | None = None,
    ) -> np.ndarray:
        """Coefficient frames at ``times`` (ascending), linear between grid points (``kept``:
        see ``grid``)."""
        low, fraction, top = _sampled(times, self.rate)
        grid = self.grid(spans, path, int(low[0]), top, kept)
        return _interpolated(grid, low, fraction, top)


def smooth_join(fitted: np.ndarray, weights: np.ndarray, smoothness: float) -> np.ndarray:
    """argmin_g Σ_t weights_t (g_t − f_t)² + smoothness Σ_t (g_{t−1} − 2g_t + g_{t+1})² for
    every column of ``fitted`` (n, K): the normal equations (diag(W) + λ D²ᵀD²) g = W f are
    pentadiagonal, one banded Cholesky solve with K right-hand sides. The factor is kept per
    weight pattern (``_normal_factor``) and only the substitutions run
    (``numerics.banded.solve_with_factor``, ``solve_spd_banded``'s solution to the last
    bit); a pattern without a factor goes the general way, which raises."""
    key = tuple(weights.tolist())
    factor = _normal_factor(key, smoothness)
    rhs = weights[:, None] * fitted
    if factor is not None:
        return solve_with_factor(factor, rhs)
    return solve_spd_banded(_normal_bands(key, smoothness), rhs)


@lru_cache(maxsize=256)
def _normal_bands(weights: tuple[float, ...], smoothness: float) -> np.ndarray:
    """The lower bands of diag(W) + λ D²ᵀD² (a join has few distinct weight patterns)."""
    n = len(weights)
    curvature = np.zeros((n - 2, n))
    for row in range(n - 2):
        curvature[row, row : row + 3] = CURVATURE
    normal = np.diag(weights) + smoothness * curvature.T @ curvature
    bands = np.zeros((3, n))
    for offset in range(3):
        bands[offset, : n - offset] = np.diagonal(normal, -offset)
    bands.setflags(write=False)
    return bands


@lru_cache(maxsize=256)
def _normal_factor(weights: tuple[float, ...], smoothness: float) -> BandedFactor | None:
    """The banded Cholesky factor of ``_normal_bands`` (None when it fails)."""
    return factor_spd_banded(_normal_bands(weights, smoothness))


@njit(cache=True)
def warped_points(
    frames: np.ndarray,
    offsets: np.ndarray,
    node: int,
    low: int,
    high: int,
    rate: float,
    start: float,
    end: float,
) -> np.ndarray:
    """``nodes.warp_node`` of ``node``'s frames at the grid points low .. high − 1 (times
    g / ``rate``) of a span [``start``, ``end``), (high − low, K): the same operations on
    each element as the array expression, in one compiled loop."""
    first = offsets[node]
    last = offsets[node + 1] - first - 1
    out = np.empty((max(high - low, 0), frames.shape[1]))
    length = end - start
    for i in range(high - low):
        position = min(max(((low + i) / rate - start) / length, 0.0), 1.0) * last
        below, above, fraction = bracket(position, last)
        blend_into(out[i], frames, first + below, first + above, fraction)
    return out


@njit(cache=True)
def _sampled(times: np.ndarray, rate: float) -> tuple[np.ndarray, np.ndarray, int]:
    """Each time's grid point at or before it (``low``), its fraction of the way to the next
    (0 within ``_EPS`` of a point), and the last grid point the times read (``top``)."""
    count = len(times)
    low = np.empty(count, dtype=np.int64)
    fraction = np.empty(count)
    top = -(2**62)
    for i in range(count):
        position = times[i] * rate
        point = int(np.floor(position + _EPS))
        step = position - point
        low[i] = point
        fraction[i] = step if step > _EPS else 0.0
        top = max(top, point + 1 if fraction[i] > 0 else point)
    return low, fraction, top


@njit(cache=True)
def _interpolated(grid: np.ndarray, low: np.ndarray, fraction: np.ndarray, top: int) -> np.ndarray:
    """Frames linear between grid points: grid[low] + fraction · (grid[low + 1] − grid[low]),
    grid's rows from point low[0] on, element by element as the array expression."""
    out = np.empty((len(low), grid.shape[1]))
    for i in range(len(low)):
        base = low[i] - low[0]
        following = min(low[i] + 1, top) - low[0]
        # the line form the frames were made with (blend_into rounds differently)
        extend_into(out[i], grid, base, following, fraction[i])
    return out


def _span_at(spans: Sequence[PhonemeSpan], t: float) -> int:
    """The first span ending after ``t`` (the last span if none), by bisection."""
    return min(bisect_right(spans, t, key=_end), len(spans) - 1)
