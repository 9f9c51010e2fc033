"""The expressive-dp phoneme-map and contamination routes against one real server
(``lipstream serve`` in a subprocess): maps, picking, candidates, contamination round trips,
and constraints carried by /v1/synthesize."""

from __future__ import annotations

import base64
import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest

from lipstream.corpus import Corpus
from lipstream.engines.expressive_dp import ExpressiveDpModel
from lipstream.phonemes import PHONEME_INDEX
from tests.live_server import LiveServer, live_server

CHARACTER = "demo"


@pytest.fixture(scope="module")
def model(expressive_dp_model: ExpressiveDpModel) -> ExpressiveDpModel:
    return expressive_dp_model


@pytest.fixture(scope="module")
def server(expressive_dp_dir: Path) -> Iterator[LiveServer]:
    with live_server(expressive_dp_dir) as running:
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


def test_the_summary_counts_each_phonemes_frames_and_clean_nodes(
    server: LiveServer, model: ExpressiveDpModel
) -> None:
    nodes = model.nodes
    first = int(np.flatnonzero(nodes.phoneme == PHONEME_INDEX["AA"])[0])
    assert _post(server, "contamination", {"mark": [first]}).status_code == 200
    try:
        answer = httpx.get(_url(server, "phoneme-maps"), timeout=30.0).json()
    finally:
        _post(server, "contamination", {"restore": [first]})
    listed = {row["phoneme"]: row for row in answer["phonemes"]}
    lengths = nodes.offsets[1:] - nodes.offsets[:-1]
    for label, index in PHONEME_INDEX.items():
        members = [node for node in range(nodes.size) if nodes.phoneme[node] == index]
        if not members:
            assert label not in listed
            continue
        row = listed[label]
        assert row["node_count"] == len(members)
        assert row["frame_count"] == sum(int(lengths[node]) for node in members)
        assert row["clean_node_count"] == len(members) - (label == "AA")
    assert answer["node_count"] == nodes.size


def test_a_node_clip_is_its_frames_in_channels(
    server: LiveServer, model: ExpressiveDpModel
) -> None:
    node = int(np.flatnonzero(model.nodes.phoneme == PHONEME_INDEX["M"])[2])
    clip = httpx.get(_url(server, f"nodes/{node}"), timeout=30.0).json()
    coefficients = model.nodes.frames[model.nodes.offsets[node] : model.nodes.offsets[node + 1]]
    by_hand = model.basis.mean + coefficients @ model.basis.components
    np.testing.assert_allclose(np.array(clip["frames"]), by_hand, atol=1e-9)
    assert (clip["phoneme"], clip["fps"], clip["contaminated"]) == ("M", model.nodes.fps, False)
    assert clip["channels"] == list(model.channels)
    missing = httpx.get(_url(server, f"nodes/{model.nodes.size}"), timeout=30.0)
    assert (
        missing.status_code == 422 and str(model.nodes.size) in missing.json()["error"]["message"]
    )


def test_an_utterance_gives_the_spans_constraints_are_numbered_by(server: LiveServer) -> None:
    spoken = _post(server, "phoneme-maps/utterance", {"text": "Hello there."}).json()
    items, speech = spoken["items"], spoken["speech"]
    seconds = len(base64.b64decode(speech["pcm16"])) / 2 / speech["sample_rate"]
    assert items[0]["start"] == 0.0 and items[-1]["end"] == pytest.approx(seconds, abs=1e-3)
    assert all(a["end"] == b["start"] for a, b in zip(items, items[1:]))
    spoken_labels = [item["phoneme"] for item in items if item["phoneme"] != "sil"]
    assert spoken_labels[:2] == ["HH", "AH"]  # espeak-ng: h@loU
    words = {"timings": [{"word": "mama", "start": 0.2, "end": 0.7}], "format": "words"}
    timed = _post(server, "phoneme-maps/utterance", {"words": words}).json()["items"]
    assert [item["phoneme"] for item in timed if item["phoneme"] != "sil"][:2] == ["M", "AA"]
    spoken_span = [item for item in timed if item["phoneme"] != "sil"]
    assert spoken_span[0]["start"] == pytest.approx(0.2) and spoken_span[-1][
        "end"
    ] == pytest.approx(0.7)
    empty = _post(server, "phoneme-maps/utterance", {"text": 7})
    assert empty.status_code == 422 and "text" in empty.json()["error"]["message"]
