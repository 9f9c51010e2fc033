"""PQ-Matching(h): exact inside its window (against brute force), never below greedy."""

from __future__ import annotations

from itertools import pairwise, product

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from lipstream.engines.anime_graph.costs import Poses, Ranking
from lipstream.engines.anime_graph.graph import AnimeGraph
from lipstream.engines.anime_graph.index import SuffixIndex
from lipstream.engines.anime_graph.pq import pq_matching, pq_window
from lipstream.engines.anime_graph.search import SuffixMatcher, count_jumps, greedy_matching

ALPHABET = 3


def _database(seed: int, audio: bool) -> tuple[AnimeGraph, Ranking, np.ndarray, SuffixIndex]:
    rng = np.random.default_rng(seed)
    lengths = rng.integers(1, 6, rng.integers(2, 5))
    labels = rng.integers(0, ALPHABET, lengths.sum()).astype(np.int16)
    utterance = np.repeat(np.arange(len(lengths)), lengths).astype(np.int32)
    successor = np.where(
        np.append(utterance[1:] == utterance[:-1], False), np.arange(1, len(labels) + 1), -1
    ).astype(np.int32)
    graph = AnimeGraph.build(labels, successor, ALPHABET)
    poses = Poses(rng.normal(size=(len(labels), 2)), rng.normal(size=(len(labels), 2)), successor)
    summaries = rng.normal(size=(len(labels), 3))
    query_summaries = rng.normal(size=(12, 3)) if audio else None
    ranking = Ranking(graph, poses, summaries, query_summaries)
    return graph, ranking, labels, SuffixIndex.build(labels, utterance, ALPHABET)


def _objective(
    graph: AnimeGraph,
    ranking: Ranking,
    nodes: tuple[int, ...],
    start: int,
    query: list[int],
    anchor: int | None,
) -> tuple[int, float]:
    """(jumps, cost) of a window's node sequence, computed from first principles."""
    chain = ([anchor] if anchor is not None else []) + list(nodes)
    jumps = sum(int(graph.successor[a] != b) for a, b in pairwise(chain))
    cost = sum(
        float(ranking.node_costs(np.array([node]), start + i, query[start + i])[0])
        for i, node in enumerate(nodes)
    )
    cost += sum(
        float(ranking.join_costs(np.array([a]), np.array([b]))[0]) for a, b in pairwise(chain)
    )
    return jumps, cost


@settings(max_examples=120, deadline=None)
@given(seed=st.integers(0, 2**16), audio=st.booleans(), window=st.integers(1, 4), data=st.data())
def test_pq_window_is_exact(seed: int, audio: bool, window: int, data: st.DataObject) -> None:
    graph, ranking, labels, _ = _database(seed, audio)
    present = sorted(set(labels.tolist()))
    query = data.draw(st.lists(st.sampled_from(present), min_size=window + 1, max_size=8))
    start = data.draw(st.integers(0, len(query) - window))
    anchor = data.draw(st.one_of(st.none(), st.integers(0, len(labels) - 1)))
    result = pq_window(graph, ranking, query, start, start + window, anchor)
    assert labels[result.nodes].tolist() == query[start : start + window]
    found = _objective(graph, ranking, tuple(int(n) for n in result.nodes), start, query, anchor)
    assert found[0] == result.jumps
    assert abs(found[1] - result.cost) < 1e-9
    choices = [graph.nodes_with_label(label).tolist() for label in query[start : start + window]]
    best = min(
        _objective(graph, ranking, nodes, start, query, anchor) for nodes in product(*choices)
    )
    assert result.jumps == best[0]
    assert abs(result.cost - best[1]) < 1e-9


@settings(max_examples=80, deadline=None)
@given(seed=st.integers(0, 2**16), window=st.integers(1, 4), data=st.data())
def test_pq_matching_never_beats_greedy_on_jumps(
    seed: int, window: int, data: st.DataObject
) -> None:
    graph, ranking, labels, index = _database(seed, audio=False)
    present = sorted(set(labels.tolist()))
    query = data.draw(st.lists(st.sampled_from(present), min_size=1, max_size=10))
    advance = data.draw(st.integers(1, window))
    nodes, _ = pq_matching(graph, ranking, query, window, advance)
    assert labels[nodes].tolist() == query
    greedy = np.concatenate(greedy_matching(SuffixMatcher(index, graph), query, ranking))
    assert count_jumps(graph, nodes) >= count_jumps(graph, greedy)


def test_a_window_spanning_a_recording_has_no_jump() -> None:
    graph, ranking, labels, _ = _database(3, audio=True)
    recording = [int(a) for a in range(len(labels)) if graph.successor[a] >= 0][:1]
    first = recording[0]
    query = [int(labels[first]), int(labels[first + 1])]
    result = pq_window(graph, ranking, query, 0, 2)
    assert result.jumps == 0
    assert graph.successor[result.nodes[0]] == result.nodes[1]
