"""GreedyMatching by suffix automaton one tile at a time in numpy: the oracle that the
compiled ``SuffixMatcher.tiles`` is tested against.

Sketch: ``SuffixReference.match`` first continues the previous node's recording along its
successors for as long as it spells the query; failing that, the automaton reads the longest
run (``index_match``). ``choose`` ranks every occurrence of that run (``index_occurrences``,
at most the matcher's ``limit``) by its node costs plus the join from the previous node, lowest first;
``search.tiles_by_matches`` loops the two.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from lipstream.engines.anime_graph.costs import Labels, Ranking
from lipstream.engines.anime_graph.graph import AnimeGraph
from lipstream.engines.anime_graph.index import SuffixIndex
from lipstream.engines.anime_graph.search import Match, SuffixMatcher


class SuffixReference:
    """``match`` and ``choose`` over the index, graph and occurrence limit of ``matcher``."""

    def __init__(self, matcher: SuffixMatcher) -> None:
        self.matcher = matcher

    def match(
        self, query: Labels, start: int, stop: int, cap: int | None, previous: int | None = None
    ) -> Match:
        graph = self.matcher.graph
        if previous is not None:
            following = int(graph.successor[previous])
            length = _spelled(graph, following, query, start, stop, cap)
            if length:
                return Match(start, length, continuation=following)
        length, state = index_match(self.matcher.index, query, start, stop, cap)
        return Match(start, length, state)

    def choose(
        self, match: Match, query: Labels, previous: int | None, ranking: Ranking
    ) -> np.ndarray:
        steps = np.arange(match.length)
        if match.continuation >= 0:
            return match.continuation + steps
        index = self.matcher.index
        starts = index_occurrences(index, match.state, match.length, self.matcher.limit)
        costs = np.zeros(len(starts))
        for offset in range(match.length):
            position = match.start + offset
            costs += ranking.node_costs(starts + offset, position, int(query[position]))
        if previous is not None:
            costs += ranking.join_costs(np.full(len(starts), previous), starts)
        return int(starts[int(np.argmin(costs))]) + steps


def _spelled(
    graph: AnimeGraph, anime: int, query: Labels, start: int, stop: int, cap: int | None
) -> int:
    """How far the recording from ``anime`` on reads ``query[start:stop]`` (at most ``cap``)."""
    length = 0
    while anime >= 0 and start + length < stop and (cap is None or length < cap):
        if int(graph.labels[anime]) != int(query[start + length]):
            break
        anime, length = int(graph.successor[anime]), length + 1
    return length


def index_match(
    index: SuffixIndex,
    query: Sequence[int] | np.ndarray,
    start: int,
    stop: int,
    cap: int | None = None,
) -> tuple[int, int]:
    """Longest prefix of ``query[start:stop]`` (at most ``cap`` long) that occurs in the
    corpus: (length, automaton state after reading it)."""
    table = index.transitions
    state = length = 0
    while start + length < stop and (cap is None or length < cap):
        following = int(table[state, query[start + length]])
        if following < 0:
            break
        state, length = following, length + 1
    return length, state


def index_occurrences(
    index: SuffixIndex, state: int, length: int, limit: int | None = None
) -> np.ndarray:
    """First animes of the occurrences of the ``length``-long match ending in ``state``,
    ascending; at most ``limit``, then evenly spread over the occurrence list."""
    low, high = int(index.low[state]), int(index.high[state])
    count = high - low
    if limit is not None and count > limit:
        picks = low + (np.arange(limit, dtype=np.int64) * count) // limit
        ends = index.ends[picks]
    else:
        ends = index.ends[low:high]
    return np.sort(index.text_anime[np.asarray(ends, dtype=np.int64) - length + 1])
