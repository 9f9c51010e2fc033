"""GreedyMatching (Alg. 2): tile the query with the longest matching graph paths.

Sketch: from query position i, find the longest run Q_i..Q_i+m-1 that some
graph path spells, take the best such path, and continue at i + m. Theorem 1
of the paper: this uses the fewest tiles, so the fewest jumps. Two matchers
find the longest run:

- ``SuffixMatcher`` (unclustered graph, beyond the paper): the corpus suffix
  automaton reads the query one transition per phoneme, O(m) for a run of
  length m whatever the corpus size; the run's occurrences are one slice.
  Its ``tiles`` runs the whole loop compiled (``suffix_search``).
- ``LayeredMatcher`` (any graph; the clustered graph's LongestMatching): the
  paper's degree-bounded depth-first search from every start node at once, as
  a layered reachability pass over (node, depth) states, each visited once,
  then dynamic programming over the survivors (states on some path of the
  longest length) for the tie-break (``layered``, compiled).

Among the longest paths the lowest ``Ranking`` cost wins, then the lowest
node ids. ``cap`` bounds a tile's length so that streaming needs bounded
lookahead. After a tile the cap cut short, the next tile first continues it
along graph edges (no jump) for as long as the query allows, and only falls
back to a fresh search when no edge continues it; without a cap this never
happens (a continuable tile would have been longer), so Theorem 1 holds
exactly, while with a cap the jumps can exceed the minimum.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from ...numerics.direct_call import DirectCall
from .costs import Labels, Ranking
from .graph import AnimeGraph, SearchGraph, csr_offsets
from .index import SuffixIndex
from .layered import Layers, NodeMembers, cheapest, reach
from .suffix_search import (
    GreedySearch,
    SuffixTables,
    greedy_tiles,
    single_occurrences,
)


@dataclass(frozen=True)
class Match:
    """The longest run at ``start``: ``length`` phonemes; matcher-specific search state."""

    start: int
    length: int
    state: int = -1
    layers: tuple[np.ndarray, ...] = ()
    steps: tuple[tuple[np.ndarray, np.ndarray], ...] = ()
    continuation: int = -1


class StepMatcher(Protocol):
    """A matcher that takes one tile at a time, for ``tiles_by_matches``."""

    def match(
        self, query: Labels, start: int, stop: int, cap: int | None, previous: int | None = None
    ) -> Match:
        """The run of ``query[start:stop]`` from ``start`` (at most ``cap`` long): the one
        continuing node ``previous`` when an edge allows, else the longest."""

    def choose(
        self, match: Match, query: Labels, previous: int | None, ranking: Ranking
    ) -> np.ndarray:
        """The best path spelling the run, as node ids (match.length,)."""


class Matcher(Protocol):
    def tiles(
        self,
        query: Labels,
        start: int,
        stop: int,
        cap: int | None,
        previous: int | None,
        ranking: Ranking,
        ranked_from: int | None = None,
        final_only: bool = False,
    ) -> list[np.ndarray]:
        """GreedyMatching of ``query[start:stop]``: the tiles' node ids, in order. The first
        tile may continue ``previous``; its join is ranked from ``ranked_from`` when given
        (a node shown before in another view), else from ``previous``. ``final_only``
        leaves out a last tile that reaches ``stop`` below ``cap`` (unchosen: the input
        after ``stop`` may still extend it)."""


@dataclass
class SuffixMatcher:
    """Longest runs from the suffix automaton, the whole loop compiled (``suffix_search``);
    ``limit`` caps the occurrences ranked. The occurrences ranked for a one-phoneme run
    (``suffix_search.single_occurrences``) are listed once, since a short tile asks for
    them on most calls. The tile-by-tile numpy reference it is tested against lives in
    ``tests/lipstream/engines/anime_graph/reference.py``."""

    index: SuffixIndex
    graph: AnimeGraph
    limit: int | None = None
    tables: SuffixTables = field(init=False, repr=False)
    _greedy_tiles: DirectCall = field(init=False, repr=False)

    def __post_init__(self) -> None:
        index, limit = self.index, self.limit or 0
        transitions, low, high, ends, text_anime = (
            np.ascontiguousarray(array)
            for array in (index.transitions, index.low, index.high, index.ends, index.text_anime)
        )
        single_offsets, single_starts = single_occurrences(
            limit, transitions, low, high, ends, text_anime
        )
        self._greedy_tiles = DirectCall(greedy_tiles)  # every request's: the view fixes the types
        self.tables = SuffixTables(
            limit,
            transitions,
            low,
            high,
            ends,
            text_anime,
            single_offsets,
            single_starts,
            np.ascontiguousarray(self.graph.labels),
            np.ascontiguousarray(self.graph.successor),
        )

    def tiles(
        self,
        query: Labels,
        start: int,
        stop: int,
        cap: int | None,
        previous: int | None,
        ranking: Ranking,
        ranked_from: int | None = None,
        final_only: bool = False,
    ) -> list[np.ndarray]:
        labels = np.asarray(query[start:stop], dtype=np.int64)
        joined = previous if ranked_from is None else ranked_from
        nodes, ends, pending = self._greedy_tiles(
            labels,
            cap or 0,
            -1 if previous is None else previous,
            -1 if joined is None else joined,
            final_only,
            self.kernel_arguments(ranking, ranking.summaries_of(start, stop - start)),
        )
        if len(nodes) < stop - start and not pending:
            missing(query, start + len(nodes))
        bounds = [0, *ends.tolist()]
        return [nodes[low:high] for low, high in zip(bounds, bounds[1:])]

    def kernel_arguments(self, ranking: Ranking, summaries: np.ndarray) -> GreedySearch:
        """``greedy_tiles``'s tables and ranking, for a query whose audio ``summaries`` are
        given (``Ranking.summaries_of``)."""
        return GreedySearch(self.tables, ranking.compiled(summaries))


def missing(query: Labels, position: int) -> None:
    """Raise the error for a query phoneme no tile can spell."""
    raise ValueError(f"phoneme {query[position]} at query position {position} is not in the graph")


class LayeredMatcher:
    """LongestMatching by a layered reachability pass (``layered.reach``) and the optimal
    path among the longest by dynamic programming over its survivors
    (``layered.cheapest``), both compiled; the graph is flattened once into CSR arrays
    keyed by (node, label): the node's members with the label, and its successors that
    carry the label."""

    def __init__(self, graph: SearchGraph) -> None:
        self.graph = graph
        n_nodes = graph.n_nodes
        offsets, labels, members = graph.label_pairs()
        owners = np.repeat(np.arange(n_nodes, dtype=np.int64), np.diff(offsets))
        labels = np.asarray(labels, dtype=np.int64)
        self.n_labels = int(labels.max()) + 1 if len(labels) else 1
        keys = owners * self.n_labels + labels
        self.members = NodeMembers(
            self.n_labels,
            csr_offsets(keys, n_nodes * self.n_labels),
            np.asarray(members, dtype=np.int64)[np.argsort(keys, kind="stable")],
            np.asarray(graph.motion_of(np.arange(n_nodes)), dtype=np.int64),
        )
        self.carries = np.zeros((n_nodes, self.n_labels), dtype=np.bool_)
        self.carries[owners, labels] = True
        self.step_offsets, self.step_targets = self._steps(graph)
        # Scratch for ``reach``, shared by every thread using this matcher: safe because the
        # compiled kernels hold the GIL (none is ``nogil``) and leave it all -1.
        self._slot = np.full(n_nodes, -1, dtype=np.int64)
        self._cheapest = DirectCall(cheapest)  # every request's: the view fixes the types

    def _steps(self, graph: SearchGraph) -> tuple[np.ndarray, np.ndarray]:
        """CSR keyed by source * n_labels + label over the edges' targets with that label,
        ascending."""
        sources, targets = (np.asarray(a, dtype=np.int64) for a in graph.edge_list())
        edge, label = np.nonzero(self.carries[targets])
        keys = sources[edge] * self.n_labels + label
        order = np.lexsort((targets[edge], keys))
        return (csr_offsets(keys, graph.n_nodes * self.n_labels), targets[edge][order])

    def _first(self, label: int, previous: int | None) -> np.ndarray:
        """Start nodes: those carrying ``label``, only the ones ``previous`` links to when
        there are any."""
        if not 0 <= label < self.n_labels:
            return np.zeros(0, dtype=np.int64)
        if previous is not None:
            key = previous * self.n_labels + label
            linked = self.step_targets[self.step_offsets[key] : self.step_offsets[key + 1]]
            if len(linked):
                return linked
        return np.flatnonzero(self.carries[:, label])

    def match(
        self, query: Labels, start: int, stop: int, cap: int | None, previous: int | None = None
    ) -> Match:
        if start >= stop:
            return Match(start, 0)
        first = self._first(int(query[start]), previous)
        if not len(first):
            return Match(start, 0)
        labels = np.asarray(query[start:stop], dtype=np.int64)
        states, offsets, sources, targets = reach(
            labels, cap or 0, first, self.n_labels, self.step_offsets, self.step_targets, self._slot
        )
        return Match(start, len(offsets) - 1, layers=(states, offsets), steps=((sources, targets),))

    def choose(
        self, match: Match, query: Labels, previous: int | None, ranking: Ranking
    ) -> np.ndarray:
        (states, offsets), ((sources, targets),) = match.layers, match.steps
        labels = np.asarray(query[match.start : match.start + match.length], dtype=np.int64)
        return np.asarray(
            self._cheapest(
                labels,
                Layers(states, offsets, sources, targets),
                -1 if previous is None else previous,
                ranking.compiled(ranking.summaries_of(match.start, match.length)),
                self.members,
            )
        )

    def tiles(
        self,
        query: Labels,
        start: int,
        stop: int,
        cap: int | None,
        previous: int | None,
        ranking: Ranking,
        ranked_from: int | None = None,
        final_only: bool = False,
    ) -> list[np.ndarray]:
        return tiles_by_matches(
            self, query, start, stop, cap, previous, ranking, ranked_from, final_only
        )


def tiles_by_matches(
    matcher: StepMatcher,
    query: Labels,
    start: int,
    stop: int,
    cap: int | None,
    previous: int | None,
    ranking: Ranking,
    ranked_from: int | None = None,
    final_only: bool = False,
) -> list[np.ndarray]:
    """Algorithm 2's loop, one ``match`` and ``choose`` per tile (``LayeredMatcher.tiles``)."""
    tiles: list[np.ndarray] = []
    position = start
    joined = previous if ranked_from is None else ranked_from
    while position < stop:
        match = matcher.match(query, position, stop, cap, previous)
        if match.length == 0:
            missing(query, position)
        if final_only and position + match.length == stop and not (cap and match.length == cap):
            break
        nodes = matcher.choose(match, query, joined, ranking)
        tiles.append(nodes)
        previous = joined = int(nodes[-1])
        position += match.length
    return tiles


def greedy_matching(
    matcher: Matcher,
    query: Labels,
    ranking: Ranking,
    cap: int | None = None,
    previous: int | None = None,
) -> list[np.ndarray]:
    """GreedyMatching over the whole query: the tiles' node ids, in order."""
    return matcher.tiles(query, 0, len(query), cap, previous, ranking)


def count_jumps(graph: SearchGraph, nodes: np.ndarray) -> int:
    """Consecutive nodes that are not joined by a graph edge."""
    nodes = np.asarray(nodes)
    if len(nodes) < 2:
        return 0
    return int(np.count_nonzero(~graph.is_edge(nodes[:-1], nodes[1:])))
