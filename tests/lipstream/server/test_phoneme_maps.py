"""The expressive-dp phoneme-map and contamination routes against one real server
(``lipstream serve`` in a subprocess): maps, picking, candidates, contamination round trips,
and constraints carried by /v1/synthesize."""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any

import httpx
import numpy as np
import pytest

from lipstream.corpus import Corpus
from lipstream.engines.base import Model
from lipstream.engines.expressive_dp import ExpressiveDpModel
from lipstream.phonemes import PHONEME_INDEX
from tests.live_server import LiveServer, live_server

CHARACTER = "demo"


@pytest.fixture(scope="module")
def model(trained_models: dict[str, Model]) -> ExpressiveDpModel:
    found = trained_models["expressive-dp"]
    assert isinstance(found, ExpressiveDpModel)
    return found


@pytest.fixture(scope="module")
def server(
    model: ExpressiveDpModel, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[LiveServer]:
    directory = tmp_path_factory.mktemp("edp-served")
    model.save(directory / "expressive-dp")
    with live_server(directory) as running:
        yield running


def _url(server: LiveServer, tail: str) -> str:
    return f"{server.http}/v1/characters/{CHARACTER}/{tail}"


def _post(server: LiveServer, tail: str, body: Any) -> httpx.Response:
    return httpx.post(_url(server, tail), json=body, timeout=30.0)


def test_a_map_lists_frames_triangles_and_nodes_and_picks_them(
    server: LiveServer, model: ExpressiveDpModel
) -> None:
    answer = httpx.get(_url(server, "phoneme-maps/AA"), timeout=30.0)
    assert answer.status_code == 200
    body = answer.json()
    rows = model.maps.phoneme_rows(PHONEME_INDEX["AA"])
    assert len(body["frames"]["x"]) == len(rows) and len(body["triangles"]) > 0
    assert {node["id"] for node in body["nodes"]} == set(
        np.flatnonzero(model.nodes.phoneme == PHONEME_INDEX["AA"]).tolist()
    )
    row = int(rows[len(rows) // 2])
    x, y = model.maps.points[row]
    picked = _post(server, "phoneme-maps/AA/pick", {"x": x, "y": y}).json()
    expected = model.basis.reconstruct(model.nodes.frames[row][None])[0]
    np.testing.assert_allclose(picked["frame"], expected, atol=1e-9)
    assert int(model.maps.frame_node[row]) in picked["nodes"]
    missing = _post(server, "phoneme-maps/AA/pick", {"x": "left"})
    assert missing.status_code == 422
    assert missing.json()["error"]["code"] == "invalid_request"
    unknown = httpx.get(_url(server, "phoneme-maps/QQ"), timeout=30.0)
    assert unknown.status_code == 404 and unknown.json()["error"]["code"] == "unknown_phoneme"
    document = httpx.get(f"{server.http}/openapi.json", timeout=30.0).json()
    assert "/v1/characters/{character}/contamination" in document["paths"]
    assert "/v1/characters/{character}/phoneme-maps/{phoneme}/pick" in document["paths"]


def test_candidates_are_time_and_context_correct(
    server: LiveServer, model: ExpressiveDpModel, small_demo_corpus: Corpus
) -> None:
    spans = small_demo_corpus.split()[1].utterances[0].phones
    index = 2
    span = spans[index]
    items = [{"phoneme": s.phoneme, "start": s.start, "end": s.end} for s in spans]
    time = span.start + 0.25 * (span.end - span.start)
    body = _post(server, "phoneme-maps/candidates", {"items": items, "index": index, "time": time})
    answer = body.json()
    assert answer["relative_time"] == pytest.approx(0.25)
    assert answer["context"] == [spans[1].phoneme, span.phoneme, spans[3].phoneme]
    nodes = model.nodes
    same = (
        (nodes.phoneme == PHONEME_INDEX[span.phoneme])
        & (nodes.previous == PHONEME_INDEX[spans[1].phoneme])
        & (nodes.next == PHONEME_INDEX[spans[3].phoneme])
    )
    assert answer["context_correct"] == np.flatnonzero(same).tolist()
    assert len(answer["time_correct"]) == int(np.sum(nodes.phoneme == PHONEME_INDEX[span.phoneme]))


def _nodes(answer: httpx.Response) -> list[int]:
    return [int(node) for node in answer.json()["stats"]["engine"]["nodes"].split()]


def _synthesize(server: LiveServer, spans: list[Any], options: dict[str, Any]) -> httpx.Response:
    items = [{"phoneme": s.phoneme, "start": s.start, "end": s.end} for s in spans]
    body = {"engine": "expressive-dp", "character": CHARACTER, "fps": 60, "items": items}
    return httpx.post(
        f"{server.http}/v1/synthesize", json={**body, "options": options}, timeout=60.0
    )


def test_contamination_and_constraints_round_trip(
    server: LiveServer, model: ExpressiveDpModel, small_demo_corpus: Corpus
) -> None:
    spans = small_demo_corpus.split()[1].utterances[0].phones
    first = _nodes(_synthesize(server, spans, {}))
    marked = sorted(set(first) - {-1})[:5]  # -1: a silence has no node
    changed = _post(server, "contamination", {"mark": marked}).json()
    assert changed["nodes"] == marked
    assert httpx.get(_url(server, "contamination"), timeout=30.0).json()["nodes"] == marked
    stored = json.loads((server.models_dir / "expressive-dp" / "contamination.json").read_text())
    assert stored["nodes"] == marked
    avoided = _nodes(_synthesize(server, spans, {}))
    assert not set(avoided) & set(marked)
    node = int(np.flatnonzero(model.nodes.phoneme != PHONEME_INDEX[spans[3].phoneme])[7])
    constrained = _synthesize(server, spans, {"constraints": {"3": node}})
    assert _nodes(constrained)[3] == node
    refused = _synthesize(server, spans, {"constraints": {"3": model.nodes.size + 5}})
    error = refused.json()["error"]
    assert refused.status_code == 422 and error["code"] == "invalid_request"
    assert f"node {model.nodes.size + 5}" in error["message"]
    bad = _post(server, "contamination", {"mark": [model.nodes.size]})
    assert bad.status_code == 422 and str(model.nodes.size) in bad.json()["error"]["message"]
    assert _post(server, "contamination", {"restore": marked}).json()["nodes"] == []
    assert _nodes(_synthesize(server, spans, {})) == first
