"""GreedyMatching on the unclustered graph, compiled (numba): every tile in one call.

Sketch: the loop of ``search.greedy_matching`` with ``SuffixMatcher``, run
without returning to Python between tiles. At query position i, a tile that
the previous tile's recording continues (same labels onward) is taken as it
is; otherwise the suffix automaton is read from its root one transition per
phoneme, giving the longest run and the automaton state whose end-position
range lists every occurrence. At most ``limit`` occurrences, spread evenly
over the range, are ranked by ``costs.cheapest_run`` (audio distance, or the
pose jump from the previous tile); the cheapest, then the lowest anime id,
wins. A one-phoneme run's occurrences are read from a list made once per index
(``single_occurrences``) instead of gathered and sorted again. A query of l
phonemes costs O(l + tiles x ranked occurrences), whatever the corpus size,
and one interpreter round trip.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from .costs import TileRanking, cheapest_run


class SuffixTables(NamedTuple):
    """One view's search tables, built once by its ``SuffixMatcher``: ``limit`` (<= 0: none)
    the occurrences ranked; ``transitions``, ``low``, ``high``, ``ends`` and ``text_anime``
    its ``SuffixIndex``; ``single_offsets``/``single_starts`` the ``single_occurrences`` of
    that index and limit; ``labels`` and ``successor`` (n_animes,) its anime graph's."""

    limit: int
    transitions: np.ndarray
    low: np.ndarray
    high: np.ndarray
    ends: np.ndarray
    text_anime: np.ndarray
    single_offsets: np.ndarray
    single_starts: np.ndarray
    labels: np.ndarray
    successor: np.ndarray


class GreedySearch(NamedTuple):
    """``greedy_tiles``'s tables and ranking."""

    tables: SuffixTables
    ranking: TileRanking


@njit(cache=True)
def _continued(
    previous: int,
    query: np.ndarray,
    position: int,
    stop: int,
    cap: int,
    labels: np.ndarray,
    successor: np.ndarray,
) -> int:
    """How far the recording after anime ``previous`` reads query[position:stop]."""
    length = 0
    anime = successor[previous] if previous >= 0 else -1
    while anime >= 0 and position + length < stop and (cap <= 0 or length < cap):
        if labels[anime] != query[position + length]:
            break
        anime = successor[anime]
        length += 1
    return length


@njit(cache=True)
def _occurrences(
    state: int,
    length: int,
    limit: int,
    low: np.ndarray,
    high: np.ndarray,
    ends: np.ndarray,
    text_anime: np.ndarray,
) -> np.ndarray:
    """First animes of the run's occurrences (``SuffixIndex.ends`` of state ``state``), at
    most ``limit`` (<= 0: all) spread evenly over them, ascending."""
    first, count = low[state], high[state] - low[state]
    taken = count if limit <= 0 or count <= limit else limit
    starts = np.empty(taken, dtype=np.int64)
    for index in range(taken):
        pick = first + index if taken == count else first + (index * count) // limit
        starts[index] = text_anime[ends[pick] - length + 1]
    starts.sort()
    return starts


@njit(cache=True)
def greedy_tiles(
    query: np.ndarray,
    cap: int,
    previous: int,
    joined: int,
    final_only: bool,
    search: GreedySearch,
) -> tuple[np.ndarray, np.ndarray, bool]:
    """Tile ``query`` (l,) labels: (anime per position (l,), tile end positions (T,), and
    whether a last tile was left out as pending).

    ``cap`` <= 0 leaves tiles uncapped; ``previous`` (-1: none) is the anime before the
    query, which the first tile may continue, and ``joined`` the one its join is ranked
    from (they differ only when the query enters a view that lacks the anime shown last);
    the ranking's ``query_summaries`` are the query's (l, D). Stops early, with the last
    end short of l, at a phoneme the corpus never says. ``final_only`` leaves out a last
    tile that reaches the end of ``query`` below ``cap`` (more input may extend it): it is
    found without ranking its occurrences, which is most of a call."""
    tables, ranking = search.tables, search.ranking
    limit, transitions = tables.limit, tables.transitions
    labels, successor = tables.labels, tables.successor
    nodes = np.empty(len(query), dtype=np.int64)
    tile_ends = np.empty(len(query), dtype=np.int64)
    position = n_tiles = 0
    pending = False
    while position < len(query):
        length = _continued(previous, query, position, len(query), cap, labels, successor)
        chosen = successor[previous] if length else -1
        if length and final_only and _grows(position, length, len(query), cap):
            pending = True
            break
        if length == 0:
            state = 0
            while position + length < len(query) and (cap <= 0 or length < cap):
                label = query[position + length]
                if label < 0 or label >= transitions.shape[1] - 1:
                    break  # no phoneme: the run (and, first in a tile, the search) ends here
                following = transitions[state, label]
                if following < 0:
                    break
                state, length = following, length + 1
            if length == 0:
                break
            if final_only and _grows(position, length, len(query), cap):
                pending = True
                break
            if length == 1:  # state is the root's child by this label
                label = query[position]
                offsets = tables.single_offsets
                starts = tables.single_starts[offsets[label] : offsets[label + 1]]
            else:
                starts = _occurrences(
                    state, length, limit, tables.low, tables.high, tables.ends, tables.text_anime
                )
            chosen = starts[
                cheapest_run(
                    starts,
                    length,
                    joined,
                    ranking.use_audio,
                    ranking.query_summaries[position : position + length],
                    ranking.summaries,
                    ranking.poses,
                )
            ]
        for offset in range(length):
            nodes[position + offset] = chosen + offset
        position += length
        tile_ends[n_tiles] = position
        n_tiles += 1
        previous = joined = chosen + length - 1
    return nodes[:position], tile_ends[:n_tiles], pending


@njit(cache=True)
def single_occurrences(
    limit: int,
    transitions: np.ndarray,
    low: np.ndarray,
    high: np.ndarray,
    ends: np.ndarray,
    text_anime: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """``_occurrences`` of every one-phoneme run, as CSR by label: (offsets (n_labels + 1,),
    starts): label l's are starts[offsets[l]:offsets[l + 1]] (none when the corpus never
    says it)."""
    n_labels = transitions.shape[1] - 1
    offsets = np.zeros(n_labels + 1, dtype=np.int64)
    lists = []
    for label in range(n_labels):
        state = transitions[0, label]
        if state >= 0:
            found = _occurrences(state, 1, limit, low, high, ends, text_anime)
        else:
            found = np.empty(0, dtype=np.int64)
        lists.append(found)
        offsets[label + 1] = offsets[label] + len(found)
    starts = np.empty(offsets[n_labels], dtype=np.int64)
    for label in range(n_labels):
        starts[offsets[label] : offsets[label + 1]] = lists[label]
    return offsets, starts


@njit(cache=True)
def _grows(position: int, length: int, known: int, cap: int) -> bool:
    """Whether a tile of ``length`` at ``position`` may still grow: it reaches the end of
    the ``known`` query, below the cap."""
    return position + length == known and (cap <= 0 or length < cap)
