"""Tie-break costs: how two matchings with the same number of jumps are ranked.

Sketch (criterion 3 of §6): when the request carries audio, a node costs the
distance between the query phoneme's audio summary and the node's (for a
clustered node, its nearest member with that label); joins are free. Without
audio, nodes are free and a join costs the motion discontinuity across it,
the distance between the left fragment's last pose and the right fragment's
first pose in PCA space (zero when the two fragments follow each other in a
recording). A matching's cost is the sum over its nodes and joins.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from numba import njit

from .graph import SearchGraph

Labels = Sequence[int] | np.ndarray
"""A query: phoneme labels, (l,)."""


class Poses(NamedTuple):
    """First and last pose (n_animes, n_pc) of every anime and its ``successor`` (n_animes,);
    the compiled search reads them as one group."""

    first: np.ndarray
    last: np.ndarray
    successor: np.ndarray

    def discontinuity(self, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        """Elementwise jump in pose from anime ``left`` to anime ``right``."""
        left = np.asarray(left)
        right = np.asarray(right)
        gap = np.linalg.norm(self.last[left] - self.first[right], axis=-1)
        return np.where(self.successor[left] == right, 0.0, gap)


class TileRanking(NamedTuple):
    """A ``Ranking`` as the compiled searches read it: by audio (``use_audio``: the query's
    ``query_summaries`` (l, D) against the animes' ``summaries`` (n_animes, D)), else by
    the pose jump (``poses``)."""

    use_audio: bool
    query_summaries: np.ndarray
    summaries: np.ndarray
    poses: Poses


@dataclass
class Ranking:
    """Costs for one query. ``query_summaries`` (the audio summary (D,) of each query
    position, as an array (l, D) or a mapping) switches to audio ranking."""

    graph: SearchGraph
    poses: Poses
    anime_summaries: np.ndarray
    query_summaries: np.ndarray | Mapping[int, np.ndarray] | None = None
    _cache: dict[tuple[int, int], np.ndarray] = field(default_factory=dict, repr=False)

    @property
    def uses_audio(self) -> bool:
        return self.query_summaries is not None

    def node_costs(self, nodes: np.ndarray, position: int, label: int) -> np.ndarray:
        """Cost of showing each of ``nodes`` at query ``position`` (which has ``label``)."""
        if self.query_summaries is None:
            return np.zeros(len(nodes))
        return self.graph.audio_costs(
            np.asarray(nodes), label, self.query_summaries[position], self.anime_summaries
        )

    def label_costs(self, position: int, label: int) -> np.ndarray:
        """``node_costs`` of the whole Anime Array row of ``label``, cached per position."""
        key = (position, label)
        if key not in self._cache:
            self._cache[key] = self.node_costs(self.graph.nodes_with_label(label), position, label)
        return self._cache[key]

    def summaries_of(self, start: int, length: int) -> np.ndarray:
        """The audio summaries (length, D) of query positions start..start+length-1, float64;
        (0, 0) without audio."""
        if self.query_summaries is None:
            return np.zeros((0, 0))
        if isinstance(self.query_summaries, np.ndarray):
            rows = self.query_summaries[start : start + length]
        else:
            rows = np.stack([self.query_summaries[p] for p in range(start, start + length)])
        return np.asarray(rows, dtype=np.float64)

    def compiled(self, summaries: np.ndarray) -> TileRanking:
        """This ranking for a compiled search of a query whose audio ``summaries`` are given
        (``summaries_of``)."""
        return TileRanking(self.uses_audio, summaries, self.anime_summaries, self.poses)

    def join_costs(self, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        """Cost of each join left[i] -> right[i] between graph nodes."""
        left, right = np.broadcast_arrays(np.asarray(left), np.asarray(right))
        if self.query_summaries is not None:
            return np.zeros(left.shape)
        return self.poses.discontinuity(self.graph.motion_of(left), self.graph.motion_of(right))


@njit(cache=True, fastmath=True)
def audio_cost(
    node: int,
    label: int,
    target: np.ndarray,
    n_labels: int,
    entry_offsets: np.ndarray,
    entry_members: np.ndarray,
    summaries: np.ndarray,
) -> float:
    """Distance from ``target`` (D,) to the nearest member of ``node`` that has ``label``."""
    best = math.inf
    key = node * n_labels + label
    for entry in range(entry_offsets[key], entry_offsets[key + 1]):
        member = entry_members[entry]
        total = 0.0
        for dim in range(len(target)):
            difference = summaries[member, dim] - target[dim]
            total += difference * difference
        best = min(best, math.sqrt(total))
    return best


@njit(cache=True, fastmath=True)
def pose_jump(
    before: int, after: int, last: np.ndarray, first: np.ndarray, successor: np.ndarray
) -> float:
    """``Poses.discontinuity`` of one join, anime ``before`` -> anime ``after``."""
    if successor[before] == after:
        return 0.0
    total = 0.0
    for dim in range(last.shape[1]):
        difference = last[before, dim] - first[after, dim]
        total += difference * difference
    return math.sqrt(total)


@njit(cache=True, fastmath=True)
def cheapest_run(
    starts: np.ndarray,
    length: int,
    previous: int,
    use_audio: bool,
    query_summaries: np.ndarray,
    summaries: np.ndarray,
    poses: Poses,
) -> int:
    """Index into ``starts`` of the cheapest recording run starts[s] .. starts[s] + length - 1
    (anime ids) shown at ``length`` query positions with audio summaries (length, D): the
    least sum of audio distances, or without audio the least pose jump from ``previous``
    (>= 0; none: every run costs 0); the first such on ties. A run is dropped as soon as
    its partial sum exceeds the best total (distances are never negative), which leaves
    the answer unchanged and skips most summary rows."""
    best, best_cost = 0, math.inf
    for index in range(len(starts)):
        start = starts[index]
        total = 0.0
        if use_audio:
            for offset in range(length):
                anime = start + offset
                distance = 0.0
                for dim in range(query_summaries.shape[1]):
                    difference = summaries[anime, dim] - query_summaries[offset, dim]
                    distance += difference * difference
                total += math.sqrt(distance)
                if total > best_cost:
                    break
        elif previous >= 0:
            total = pose_jump(previous, start, poses.last, poses.first, poses.successor)
        if total < best_cost:
            best, best_cost = index, total
    return best
