"""GreedyMatching against exhaustive references, the suffix index, and tie-breaking."""

from __future__ import annotations

from itertools import pairwise, product

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lipstream.engines.anime_graph.costs import Poses, Ranking
from lipstream.engines.anime_graph.graph import AnimeGraph, ClusterGraph, SearchGraph
from lipstream.engines.anime_graph.index import SuffixIndex
from lipstream.engines.anime_graph.search import (
    LayeredMatcher,
    SuffixMatcher,
    count_jumps,
    greedy_matching,
    tiles_by_matches,
)
from tests.lipstream.engines.anime_graph.reference import (
    SuffixReference,
    index_match,
    index_occurrences,
)

ALPHABET = 4


def _successor(utterance: np.ndarray) -> np.ndarray:
    following = np.arange(1, len(utterance) + 1)
    same = np.append(utterance[1:] == utterance[:-1], False)
    return np.where(same, following, -1).astype(np.int32)


Database = tuple[np.ndarray, np.ndarray, list[int]]


@st.composite
def databases(draw: st.DrawFn) -> Database:
    """(labels, utterance, query): recordings over a small alphabet and a query whose
    labels all occur in them."""
    recordings = draw(
        st.lists(
            st.lists(st.integers(0, ALPHABET - 1), min_size=1, max_size=7), min_size=1, max_size=4
        )
    )
    labels = np.array([label for recording in recordings for label in recording], dtype=np.int16)
    utterance = np.repeat(np.arange(len(recordings)), [len(r) for r in recordings])
    present = sorted(set(labels.tolist()))
    query = draw(st.lists(st.sampled_from(present), min_size=1, max_size=10))
    return labels, utterance.astype(np.int32), query


def _ranking(graph: SearchGraph, n_animes: int, successor: np.ndarray, seed: int = 0) -> Ranking:
    rng = np.random.default_rng(seed)
    poses = Poses(rng.normal(size=(n_animes, 2)), rng.normal(size=(n_animes, 2)), successor)
    return Ranking(graph, poses, np.zeros((n_animes, 0)))


def _min_jumps(graph: SearchGraph, query: list[int]) -> int:
    """Exhaustive minimum over all node sequences spelling the query (dynamic programming
    over (position, node) of the fewest jumps so far)."""
    best = {int(node): 0 for node in graph.nodes_with_label(query[0])}
    for label in query[1:]:
        nodes = graph.nodes_with_label(label)
        best = {
            int(node): min(
                jumps + int(not graph.is_edge(np.array([previous]), np.array([node]))[0])
                for previous, jumps in best.items()
            )
            for node in nodes
        }
    return min(best.values())


def _min_tiles(
    labels: np.ndarray, utterance: np.ndarray, query: list[int], cap: int | None = None
) -> int:
    """Fewest substrings of the recordings that concatenate to the query, by trying every
    split point (dynamic programming over all tilings)."""
    texts = [tuple(labels[utterance == u].tolist()) for u in np.unique(utterance)]

    def occurs(piece: tuple[int, ...]) -> bool:
        return any(
            text[i : i + len(piece)] == piece
            for text in texts
            for i in range(len(text) - len(piece) + 1)
        )

    fewest = [0] + [10**9] * len(query)
    for stop in range(1, len(query) + 1):
        for start in range(stop):
            piece = tuple(query[start:stop])
            if (cap is None or len(piece) <= cap) and occurs(piece):
                fewest[stop] = min(fewest[stop], fewest[start] + 1)
    return fewest[-1]


@settings(max_examples=200, deadline=None)
@given(databases())
def test_greedy_uses_the_minimum_number_of_jumps(database: Database) -> None:
    labels, utterance, query = database
    successor = _successor(utterance)
    graph = AnimeGraph.build(labels, successor, ALPHABET)
    index = SuffixIndex.build(labels, utterance, ALPHABET)
    ranking = _ranking(graph, len(labels), successor)
    fewest_tiles = _min_tiles(labels, utterance, query)
    for matcher in (SuffixMatcher(index, graph), LayeredMatcher(graph)):
        tiles = greedy_matching(matcher, query, ranking)
        nodes = np.concatenate(tiles)
        assert labels[nodes].tolist() == query
        assert len(tiles) == fewest_tiles
        assert count_jumps(graph, nodes) == _min_jumps(graph, query) == fewest_tiles - 1


@settings(max_examples=150, deadline=None)
@given(databases(), st.integers(1, 3))
def test_capped_greedy_continues_a_cut_tile_and_matches_uncapped_below_the_cap(
    database: Database, cap: int
) -> None:
    labels, utterance, query = database
    successor = _successor(utterance)
    graph = AnimeGraph.build(labels, successor, ALPHABET)
    matcher = SuffixMatcher(SuffixIndex.build(labels, utterance, ALPHABET), graph)
    ranking = _ranking(graph, len(labels), successor)
    tiles = greedy_matching(matcher, query, ranking, cap=cap)
    assert labels[np.concatenate(tiles)].tolist() == query
    assert all(len(tile) <= cap for tile in tiles)
    for before, after in pairwise(tiles):
        following = successor[before[-1]]
        if following >= 0 and labels[following] == labels[after[0]]:
            assert after[0] == following, "a tile that can be continued is continued"
    free = greedy_matching(matcher, query, ranking)
    if max(len(tile) for tile in free) < cap:
        assert [t.tolist() for t in tiles] == [t.tolist() for t in free]


@settings(max_examples=150, deadline=None)
@given(databases(), st.integers(1, 6), st.integers(0, 2**16))
def test_greedy_on_a_clustered_graph_uses_the_minimum_number_of_jumps(
    database: Database, k: int, seed: int
) -> None:
    labels, utterance, query = database
    successor = _successor(utterance)
    rng = np.random.default_rng(seed)
    assignment = rng.integers(0, k, len(labels))
    used = np.unique(assignment)
    assignment = np.searchsorted(used, assignment)
    representative = np.array([np.flatnonzero(assignment == c)[0] for c in range(len(used))])
    graph = ClusterGraph.build(assignment, representative, labels, successor, ALPHABET)
    tiles = greedy_matching(LayeredMatcher(graph), query, _ranking(graph, len(labels), successor))
    nodes = np.concatenate(tiles)
    assert all(graph.has_label(nodes[i : i + 1], label)[0] for i, label in enumerate(query))
    assert count_jumps(graph, nodes) == _min_jumps(graph, query) == len(tiles) - 1


@settings(max_examples=150, deadline=None)
@given(databases(), st.data())
def test_suffix_index_finds_every_occurrence(database: Database, data: st.DataObject) -> None:
    labels, utterance, _ = database
    index = SuffixIndex.build(labels, utterance, ALPHABET)
    pattern = data.draw(st.lists(st.integers(0, ALPHABET - 1), min_size=1, max_size=4))
    length, state = index_match(index, pattern, 0, len(pattern))
    expected = [
        start
        for start in range(len(labels))
        if labels[start : start + len(pattern)].tolist() == pattern
        and len(set(utterance[start : start + len(pattern)].tolist())) == 1
    ]
    if expected:
        assert length == len(pattern)
        assert index_occurrences(index, state, length).tolist() == expected
    else:
        assert length < len(pattern)


def _two_way_database() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Recordings 0: [0 1 2], 1: [3 0 1], 2: [0 1 3]: the run (0 1) occurs at animes 0, 4, 6."""
    labels = np.array([0, 1, 2, 3, 0, 1, 0, 1, 3], dtype=np.int16)
    utterance = np.array([0, 0, 0, 1, 1, 1, 2, 2, 2], dtype=np.int32)
    return labels, utterance, _successor(utterance)


def test_ties_go_to_the_closest_audio_then_to_the_lowest_anime() -> None:
    labels, utterance, successor = _two_way_database()
    graph = AnimeGraph.build(labels, successor, ALPHABET)
    matcher = SuffixMatcher(SuffixIndex.build(labels, utterance, ALPHABET), graph)
    poses = Poses(np.zeros((9, 1)), np.zeros((9, 1)), successor)
    summaries = np.zeros((9, 1))
    summaries[[4, 5]] = 1.0
    query = [0, 1]
    near_four = Ranking(graph, poses, summaries, np.array([[0.9], [1.2]]))
    assert greedy_matching(matcher, query, near_four)[0].tolist() == [4, 5]
    tied = Ranking(graph, poses, summaries, np.array([[0.0], [0.0]]))
    assert greedy_matching(matcher, query, tied)[0].tolist() == [0, 1]
    layered = greedy_matching(LayeredMatcher(graph), query, near_four)
    assert layered[0].tolist() == [4, 5]


def test_without_audio_ties_go_to_the_smoothest_join() -> None:
    labels, utterance, successor = _two_way_database()
    graph = AnimeGraph.build(labels, successor, ALPHABET)
    matcher = SuffixMatcher(SuffixIndex.build(labels, utterance, ALPHABET), graph)
    first = np.zeros((9, 1))
    last = np.zeros((9, 1))
    last[2] = 5.0
    first[[0, 4, 6]] = [[0.0], [7.0], [4.5]]
    ranking = Ranking(graph, Poses(first, last, successor), np.zeros((9, 0)))
    tiles = greedy_matching(matcher, [2, 0, 1], ranking)
    assert [tile.tolist() for tile in tiles] == [[2], [6, 7]]
    assert [t.tolist() for t in greedy_matching(matcher, [2, 0, 1], ranking)] == [
        t.tolist() for t in tiles
    ]


def test_a_capped_tile_resumes_its_recording() -> None:
    labels = np.array([0, 1, 2, 3, 1, 2, 3], dtype=np.int16)
    utterance = np.array([0, 0, 0, 0, 1, 1, 1], dtype=np.int32)
    successor = _successor(utterance)
    graph = AnimeGraph.build(labels, successor, ALPHABET)
    matcher = SuffixMatcher(SuffixIndex.build(labels, utterance, ALPHABET), graph)
    poses = Poses(np.zeros((7, 1)), np.zeros((7, 1)), successor)
    summaries = np.zeros((7, 1))
    summaries[[4, 5, 6]] = 1.0
    ranking = Ranking(graph, poses, summaries, np.ones((4, 1)))
    tiles = greedy_matching(matcher, [0, 1, 2, 3], ranking, cap=2)
    assert [tile.tolist() for tile in tiles] == [[0, 1], [2, 3]]
    assert count_jumps(graph, np.concatenate(tiles)) == 0


def test_occurrence_limit_spreads_over_the_occurrences() -> None:
    labels = np.zeros(40, dtype=np.int16)
    utterance = np.arange(40, dtype=np.int32)
    index = SuffixIndex.build(labels, utterance, 1)
    length, state = index_match(index, [0], 0, 1)
    everything = index_occurrences(index, state, length)
    assert everything.tolist() == list(range(40))
    chosen = index_occurrences(index, state, length, limit=8)
    assert len(chosen) == 8 and len(set(chosen.tolist())) == 8
    assert set(chosen.tolist()) <= set(everything.tolist())


def test_every_labelling_of_a_tiny_graph_has_at_least_greedys_jumps() -> None:
    labels, utterance, successor = _two_way_database()
    graph = AnimeGraph.build(labels, successor, ALPHABET)
    matcher = SuffixMatcher(SuffixIndex.build(labels, utterance, ALPHABET), graph)
    query = [3, 0, 1, 2, 3, 0]
    greedy = count_jumps(
        graph, np.concatenate(greedy_matching(matcher, query, _ranking(graph, 9, successor)))
    )
    choices = [graph.nodes_with_label(label).tolist() for label in query]
    brute = min(count_jumps(graph, np.array(nodes)) for nodes in product(*choices))
    assert greedy == brute == 2


def _clustered(labels: np.ndarray, successor: np.ndarray, k: int, seed: int) -> ClusterGraph:
    assignment = np.random.default_rng(seed).integers(0, k, len(labels))
    assignment = np.searchsorted(np.unique(assignment), assignment)
    representative = np.array(
        [np.flatnonzero(assignment == c)[0] for c in range(int(assignment.max()) + 1)]
    )
    return ClusterGraph.build(assignment, representative, labels, successor, ALPHABET)


def _paths(graph: SearchGraph, run: list[int], previous: int | None) -> list[tuple[int, ...]]:
    """Every node sequence spelling ``run`` along graph edges; only those starting at a
    successor of ``previous`` when some successor carries the run's first label."""
    starts = graph.nodes_with_label(run[0]).tolist()
    if previous is not None:
        linked = [
            node for node in starts if graph.is_edge(np.array([previous]), np.array([node]))[0]
        ]
        starts = linked or starts
    paths: list[tuple[int, ...]] = [(node,) for node in starts]
    for label in run[1:]:
        paths = [
            path + (int(node),)
            for path in paths
            for node in graph.successors_of(np.array([path[-1]]))[1]
            if graph.has_label(np.array([node]), label)[0]
        ]
    return paths


def _path_cost(
    ranking: Ranking, nodes: tuple[int, ...], run: list[int], previous: int | None
) -> float:
    cost = sum(
        float(ranking.node_costs(np.array([node]), i, run[i])[0]) for i, node in enumerate(nodes)
    )
    joins = list(zip(nodes, nodes[1:]))
    if previous is not None:
        joins.insert(0, (previous, nodes[0]))
    return cost + sum(float(ranking.join_costs(np.array([a]), np.array([b]))[0]) for a, b in joins)


@settings(max_examples=120, deadline=None)
@given(databases(), st.integers(1, 6), st.integers(0, 2**16), st.booleans(), st.data())
def test_layered_matcher_takes_the_cheapest_of_the_longest_paths(
    database: Database, k: int, seed: int, audio: bool, data: st.DataObject
) -> None:
    labels, utterance, query = database
    query = query[:6]
    successor = _successor(utterance)
    graph = _clustered(labels, successor, k, seed)
    rng = np.random.default_rng(seed)
    poses = Poses(rng.normal(size=(len(labels), 2)), rng.normal(size=(len(labels), 2)), successor)
    ranking = Ranking(
        graph,
        poses,
        rng.normal(size=(len(labels), 3)),
        rng.normal(size=(len(query), 3)) if audio else None,
    )
    previous = data.draw(st.none() | st.integers(0, graph.n_nodes - 1))
    matcher = LayeredMatcher(graph)
    match = matcher.match(query, 0, len(query), None, previous)
    longest = max(m for m in range(1, len(query) + 1) if _paths(graph, query[:m], previous))
    assert match.length == longest
    run = query[:longest]
    chosen = tuple(int(node) for node in matcher.choose(match, query, previous, ranking))
    candidates = _paths(graph, run, previous)
    assert chosen in candidates
    cheapest = min(_path_cost(ranking, path, run, previous) for path in candidates)
    assert _path_cost(ranking, chosen, run, previous) <= cheapest + 1e-9


@settings(max_examples=100, deadline=None)
@given(databases(), st.integers(1, 6), st.integers(0, 2**16))
def test_layered_ties_go_to_the_lowest_last_node_then_the_lowest_predecessors(
    database: Database, k: int, seed: int
) -> None:
    labels, utterance, query = database
    query = query[:6]
    successor = _successor(utterance)
    graph = _clustered(labels, successor, k, seed)
    flat = Poses(np.zeros((len(labels), 1)), np.zeros((len(labels), 1)), successor)
    tied = Ranking(graph, flat, np.zeros((len(labels), 0)))
    matcher = LayeredMatcher(graph)
    match = matcher.match(query, 0, len(query), None)
    chosen = tuple(int(node) for node in matcher.choose(match, query, None, tied))
    expected = min(_paths(graph, query[: match.length], None), key=lambda p: p[::-1])
    assert chosen == expected


def test_clustered_audio_costs_at_are_each_nodes_nearest_member_per_label() -> None:
    labels = np.array([0, 1, 0, 1, 2, 0], dtype=np.int16)
    successor = np.array([1, 2, -1, 4, 5, -1], dtype=np.int32)
    assignment = np.array([0, 0, 1, 1, 0, 1])
    graph = ClusterGraph.build(assignment, np.array([0, 2]), labels, successor, 3)
    summaries = np.array([[0.0], [1.0], [2.0], [3.0], [4.0], [5.0]])
    targets = np.array([[2.5], [2.5], [0.0], [10.0]])
    costs = graph.audio_costs_at(np.array([0, 1, 0, 1]), np.array([0, 0, 1, 2]), targets, summaries)
    # node 0 label 0: animes {0} -> 2.5; node 1 label 0: {2, 5} -> 0.5;
    # node 0 label 1: {1} -> 1.0; node 1 has no label 2 -> inf
    assert costs.tolist() == [2.5, 0.5, 1.0, np.inf]
    single = graph.audio_costs(np.array([0, 1]), 0, np.array([4.0]), summaries)
    assert single.tolist() == [4.0, 1.0]


@settings(max_examples=150, deadline=None)
@given(databases(), st.integers(0, 3), st.booleans(), st.integers(0, 2**16), st.data())
def test_compiled_tiles_equal_the_match_and_choose_loop(
    database: Database, cap: int, audio: bool, seed: int, data: st.DataObject
) -> None:
    labels, utterance, query = database
    successor = _successor(utterance)
    graph = AnimeGraph.build(labels, successor, ALPHABET)
    limit = data.draw(st.sampled_from([None, 1, 2]))
    matcher = SuffixMatcher(SuffixIndex.build(labels, utterance, ALPHABET), graph, limit)
    rng = np.random.default_rng(seed)
    poses = Poses(rng.normal(size=(len(labels), 2)), rng.normal(size=(len(labels), 2)), successor)
    summaries = rng.normal(size=(len(labels), 3))
    ranking = Ranking(graph, poses, summaries, rng.normal(size=(len(query), 3)) if audio else None)
    previous = data.draw(st.none() | st.integers(0, len(labels) - 1))
    ranked_from = data.draw(st.none() | st.integers(0, len(labels) - 1))
    compiled = matcher.tiles(query, 0, len(query), cap or None, previous, ranking, ranked_from)
    stepwise = SuffixReference(matcher)
    reference = tiles_by_matches(
        stepwise, query, 0, len(query), cap or None, previous, ranking, ranked_from
    )
    assert [t.tolist() for t in compiled] == [t.tolist() for t in reference]
    # final_only: the same tiles less a last one that reaches the end below the cap
    final = [t.tolist() for t in reference]
    if final and len(final[-1]) != (cap or None):
        final.pop()
    args = (query, 0, len(query), cap or None, previous, ranking, ranked_from, True)
    assert [t.tolist() for t in matcher.tiles(*args)] == final
    assert [t.tolist() for t in tiles_by_matches(stepwise, *args)] == final


def test_a_phoneme_missing_from_the_corpus_is_reported_by_position() -> None:
    labels = np.array([0, 1, 2], dtype=np.int16)
    utterance = np.zeros(3, dtype=np.int32)
    graph = AnimeGraph.build(labels, _successor(utterance), ALPHABET)
    matcher = SuffixMatcher(SuffixIndex.build(labels, utterance, ALPHABET), graph)
    ranking = _ranking(graph, 3, _successor(utterance))
    with pytest.raises(ValueError, match="phoneme 3 at query position 2"):
        greedy_matching(matcher, [0, 1, 3], ranking)


@pytest.mark.parametrize("label", [ALPHABET + 3, -1])
def test_a_label_outside_the_alphabet_stops_every_matcher_where_it_stands(label: int) -> None:
    labels = np.array([0, 1, 2, 0, 1], dtype=np.int16)
    utterance = np.zeros(5, dtype=np.int32)
    successor = _successor(utterance)
    graph = AnimeGraph.build(labels, successor, ALPHABET)
    clustered = ClusterGraph.build(np.arange(5), np.arange(5), labels, successor, ALPHABET)
    for matcher, searched in (
        (SuffixMatcher(SuffixIndex.build(labels, utterance, ALPHABET), graph), graph),
        (LayeredMatcher(clustered), clustered),
    ):
        ranking = _ranking(searched, 5, successor)
        with pytest.raises(ValueError, match=f"phoneme {label} at query position 2"):
            greedy_matching(matcher, [0, 1, label, 0], ranking)
