"""Blending at jumps (§6.3): how two fragments that never met in a recording are joined.

Sketch, for a jump from anime A_i (p frames) to A_i+1 (q frames):

- *Example pair.* Find recorded neighbours A_m -> A_n with the same two
  labels; of several, the one whose shared join pose lies nearest both
  fragments' join poses. A_m, time-warped linearly onto A_i's span, is blended
  in with weight rising 0 -> 1 across A_i; A_n, onto A_i+1's span, with
  weight falling 1 -> 0 across A_i+1. Since A_m ends where A_n starts, the
  motion is continuous at the join.
- *Fallback (no such pair).* A_i is extended by the recording that follows it
  for q frames, A_i+1 by the recording that precedes it for p frames (the end
  velocity is extrapolated where the recording stops), and the two (p+q)-frame
  curves are blended with a weight rising 0 -> 1 across both spans.

Written as corrections added to each fragment, a fragment between two jumps
takes both, each vanishing at the fragment's far end.

*Forward (causal rungs).* The join looks at nothing after the jump: over the
first half of A_i+1's span only, the recording that follows A_i is blended
out, its weight falling 1 -> 0, so the motion is continuous at the join, a
short span still reaches its own fragment's pose, and A_i's own span never
changes once it is decided.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum

import numpy as np
from numba import njit

from .costs import Poses
from .graph import csr_offsets


class JoinKind(Enum):
    SEAMLESS = "seamless"
    CUT = "cut"
    PAIR = "pair"
    EXTEND = "extend"
    FORWARD = "forward"


@dataclass(frozen=True)
class Join:
    """How the fragments at positions j and j+1 meet; ``left_example`` (A_m) and
    ``right_example`` (A_n) are anime ids for ``JoinKind.PAIR``."""

    kind: JoinKind
    left_example: int = -1
    right_example: int = -1


@dataclass(frozen=True)
class PairIndex:
    """Recorded neighbour pairs (m, successor m) grouped by their label bigram:
    bigram a * n_labels + b owns ``sources[offsets[key]:offsets[key + 1]]`` (ascending)."""

    offsets: np.ndarray
    sources: np.ndarray
    n_labels: int

    @classmethod
    def build(
        cls,
        labels: np.ndarray,
        successor: np.ndarray,
        n_labels: int,
        members: np.ndarray | None = None,
    ) -> PairIndex:
        """Pairs among ``members`` (anime ids; default all)."""
        chosen = np.arange(len(labels)) if members is None else np.asarray(members)
        linked = chosen[successor[chosen] >= 0]
        keys = labels[linked].astype(np.int64) * n_labels + labels[successor[linked]]
        order = np.argsort(keys, kind="stable")
        offsets = csr_offsets(keys, n_labels * n_labels)
        return cls(offsets, linked[order].astype(np.int32), n_labels)

    def pairs(self, left_label: int, right_label: int, limit: int | None = None) -> np.ndarray:
        key = left_label * self.n_labels + right_label
        low, high = int(self.offsets[key]), int(self.offsets[key + 1])
        if limit is not None and high - low > limit:
            return self.sources[low + (np.arange(limit) * (high - low)) // limit]
        return self.sources[low:high]


def plan_join(
    left: int,
    right: int,
    poses: Poses,
    pairs_of: Callable[[], tuple[tuple[int, int], PairIndex]],
    limit: int | None,
    blend: bool,
    forward: bool = False,
) -> Join:
    """The join from fragment anime ``left`` to ``right`` (``forward``: blended inside
    ``right``'s span only); ``pairs_of`` gives the query labels of the join and the
    recorded pairs to blend it with, asked for only when a pair is sought (a causal
    request, blending forward, never seeks one)."""
    if int(poses.successor[left]) == right:
        return Join(JoinKind.SEAMLESS)
    if not blend:
        return Join(JoinKind.CUT)
    if forward:
        return Join(JoinKind.FORWARD)
    labels, pairs = pairs_of()
    if poses.last.dtype == poses.first.dtype == np.float64 and poses.last.shape[1] <= _BLOCK:
        chosen = int(
            _cheapest_pair(
                pairs.offsets,
                pairs.sources,
                labels[0] * pairs.n_labels + labels[1],
                -1 if limit is None else limit,
                poses.last,
                poses.first,
                left,
                right,
            )
        )
        if chosen < 0:
            return Join(JoinKind.EXTEND)
        return Join(JoinKind.PAIR, chosen, int(poses.successor[chosen]))
    candidates = pairs.pairs(labels[0], labels[1], limit)
    if not len(candidates):
        return Join(JoinKind.EXTEND)
    meeting = poses.last[candidates]
    cost = np.linalg.norm(meeting - poses.last[left], axis=1) + np.linalg.norm(
        meeting - poses.first[right], axis=1
    )
    chosen = int(candidates[int(np.argmin(cost))])
    return Join(JoinKind.PAIR, chosen, int(poses.successor[chosen]))


_BLOCK = 128
"""Rows up to this long numpy sums in one block (longer ones it splits in halves)."""


@njit(cache=True)
def _cheapest_pair(
    offsets: np.ndarray,
    sources: np.ndarray,
    key: int,
    limit: int,
    last: np.ndarray,
    first: np.ndarray,
    left: int,
    right: int,
) -> int:
    """``_cheapest_meeting`` of ``PairIndex.pairs`` of bigram ``key`` (at most ``limit``,
    < 0: all), picked without numpy's temporaries; -1 when there is none."""
    low, high = offsets[key], offsets[key + 1]
    count = high - low
    if limit >= 0 and count > limit:
        candidates = np.empty(limit, dtype=sources.dtype)
        for index in range(limit):
            candidates[index] = sources[low + (index * count) // limit]
    else:
        candidates = sources[low:high]
    if len(candidates) == 0:
        return -1
    return _cheapest_meeting(candidates, last, first, left, right)


@njit(cache=True)
def _cheapest_meeting(
    candidates: np.ndarray, last: np.ndarray, first: np.ndarray, left: int, right: int
) -> int:
    """The candidate m minimizing |last[m] - last[left]| + |last[m] - first[right]|, the
    first of equals: the numpy expression's value bit for bit (``_distance`` sums as
    ``np.linalg.norm`` does), without its temporaries, since a join is planned on the
    streamed call that decides a tile."""
    squares = np.empty(last.shape[1])
    best, best_cost = -1, np.inf
    for candidate in candidates:
        cost = _distance(last[candidate], last[left], squares) + _distance(
            last[candidate], first[right], squares
        )
        if best < 0 or cost < best_cost or (np.isnan(cost) and not np.isnan(best_cost)):
            best, best_cost = candidate, cost
    return best


@njit(cache=True)
def _distance(a: np.ndarray, b: np.ndarray, squares: np.ndarray) -> float:
    """Euclidean distance with numpy's row sum of at most ``_BLOCK`` squares: 0 + their
    sum in order when under 8, else eight running sums combined as a tree, then the rest
    in order."""
    for column in range(len(a)):
        squares[column] = (a[column] - b[column]) * (a[column] - b[column])
    count = len(squares)
    if count < 8:
        total = 0.0
        for column in range(count):
            total += squares[column]
        return math.sqrt(0.0 + total)
    sums = squares[:8].copy()
    column = 8
    while column < count - count % 8:
        for lane in range(8):
            sums[lane] += squares[column + lane]
        column += 8
    total = ((sums[0] + sums[1]) + (sums[2] + sums[3])) + (
        (sums[4] + sums[5]) + (sums[6] + sums[7])
    )
    for rest in range(column, count):
        total += squares[rest]
    return math.sqrt(0.0 + total)
