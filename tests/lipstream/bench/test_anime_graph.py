"""The anime-graph benchmark's paper table is assembled from what it measured."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from lipstream.bench.anime_graph import paper_table, warm_search_times_ms
from lipstream.corpus import Utterance
from lipstream.engines.anime_graph import AnimeGraphEngine
from lipstream.engines.anime_graph.model import AnimeGraphModel
from lipstream.engines.anime_graph.views import WHOLE
from lipstream.errors import InvalidRequestError
from tests.lipstream.engines.anime_graph.anime_synthetic import make_corpus, make_spans


def _brute_force_greedy(model: AnimeGraphModel, utterance: Utterance) -> tuple[int, float]:
    """(jumps, RMS) of uncapped greedy on the unclustered graph, counted by hand: a jump is
    a pair of consecutive animes where the second does not follow the first in a recording;
    RMS over every frame and channel."""
    synthesizer = model.start(fps=model.fps, graph="unclustered", max_tile=0)
    synthesizer.feed(utterance.phones, utterance.audio)
    frames = np.concatenate([synthesizer.frames(), synthesizer.finish()]).astype(np.float64)
    successor = model.views[WHOLE].anime_graph.successor
    nodes = synthesizer.nodes
    jumps = sum(successor[a] != b for a, b in zip(nodes[:-1], nodes[1:]))
    n = min(len(frames), len(utterance.frames))
    return jumps, float(np.sqrt(np.mean((frames[:n] - utterance.frames[:n]) ** 2)))


def test_the_paper_table_rows_agree_with_their_own_measurements() -> None:
    corpus = make_corpus(seed=11, n_utterances=14, length=(8, 12))
    train = replace(corpus, utterances=corpus.utterances[:12])
    heldout = replace(corpus, utterances=corpus.utterances[12:])
    model = AnimeGraphEngine(clusters=10).fit(train)
    table = paper_table(model, heldout, windows=(2, 3), repeats=3, count=2)
    assert [row["graph"] for row in table["rows"]] == ["unclustered", "clustered"] * 2
    assert sorted({row["stem"] for row in table["rows"]}) == sorted(
        u.stem for u in heldout.utterances
    )
    for row in table["rows"]:
        utterance = next(u for u in heldout.utterances if u.stem == row["stem"])
        assert row["phonemes"] == len(utterance.phones)
        greedy = row["greedy"]
        unclustered = next(
            other["greedy"]
            for other in table["rows"]
            if other["stem"] == row["stem"] and other["graph"] == "unclustered"
        )
        if row["graph"] == "unclustered":
            jumps, rms = _brute_force_greedy(model, utterance)
            assert greedy["jumps"] == jumps
            assert greedy["rms"] == pytest.approx(rms, rel=1e-5)
        assert 0 < greedy["search_ms"] and 0 < greedy["search_ms_in_synthesis"]
        assert set(row["pq"]) == {"2", "3"}
        for pq in row["pq"].values():
            assert not pq["timed_out"] and greedy["jumps"] <= pq["jumps"]
            assert pq["speedup"] == pytest.approx(pq["search_ms"] / greedy["search_ms"])
            assert pq["speedup_over_unclustered_greedy"] == pytest.approx(
                pq["search_ms"] / unclustered["search_ms"]
            )
    assert table["greedy_never_more_jumps"] is True
    assert table["min_speedup_over_pq4"] is None  # no PQ(4) was run
    assert set(table["min_speedup_over_pq4_same_graph"]) == {"unclustered", "clustered"}


def test_only_a_finished_request_can_be_re_timed() -> None:
    model = AnimeGraphEngine(clusters=0).fit(make_corpus(seed=12, n_utterances=8))
    synthesizer = model.start(fps=60.0, max_tile=0)
    synthesizer.feed(make_spans(np.random.default_rng(0), 10))
    with pytest.raises(InvalidRequestError):
        warm_search_times_ms(synthesizer, 2)
    synthesizer.finish()
    assert len(warm_search_times_ms(synthesizer, 4)) == 4
