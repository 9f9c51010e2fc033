"""``POST /v1/synthesize``, content negotiation, its errors, and the OpenAPI document."""

from __future__ import annotations

import base64
import csv
import io
import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import msgpack
import numpy as np
import pytest

from lipstream.config import ServerSettings
from lipstream.engines import engine_names
from lipstream.server.catalog import Catalog
from tests.lipstream.server.harness import Served, serving

ITEMS = [{"phoneme": "HH", "start": 0.0, "end": 0.1}, {"phoneme": "AY1", "start": 0.1, "end": 0.3}]
BODY = {"engine": "viseme-lerp", "character": "demo", "fps": 50, "items": ITEMS}
FRAMES = 16 + 8  # frames i / 50 <= 0.3 s, then the return to rest: 150 ms at 50 fps


@pytest.fixture(scope="module")
def served(all_models_dir: Path) -> Iterator[Served]:
    with serving(all_models_dir, ServerSettings(max_body_bytes=4096)) as running:
        yield running


def post(
    served: Served, body: Any, content_type: str = "application/json", accept: str | None = None
) -> httpx.Response:
    content = (
        body
        if isinstance(body, (bytes, str))
        else (msgpack.packb(body) if "msgpack" in content_type else json.dumps(body))
    )
    headers = {"Content-Type": content_type, **({"Accept": accept} if accept else {})}
    return httpx.post(f"{served.http}/v1/synthesize", content=content, headers=headers)


def test_json_in_json_out_equals_the_offline_synthesis(served: Served, catalog: Catalog) -> None:
    answer = post(served, BODY)
    assert answer.status_code == 200 and answer.headers["content-type"] == "application/json"
    result = answer.json()
    model = catalog.model("viseme-lerp", "demo")
    expected = model.synthesize([("HH", 0.0, 0.1), ("AY1", 0.1, 0.3)], fps=50).frames
    assert (result["n_frames"], result["n_channels"], result["first_frame"]) == (FRAMES, 28, 0)
    assert result["channels"] == list(model.channels)
    assert result["fidelity"] == "lerp" and result["lookahead_ms"] == 200.0
    assert np.array(result["data"][:16], dtype=np.float32).tobytes() == expected.tobytes()
    assert result["stats"]["frames"] == FRAMES


@pytest.mark.parametrize(
    ("content_type", "accept", "returned"),
    [
        ("application/msgpack", None, "application/msgpack"),
        ("application/msgpack", "application/json", "application/json"),
        (
            "application/json",
            "application/x-msgpack;q=0.9, application/json;q=0",
            "application/msgpack",
        ),
        ("application/json", "*/*", "application/json"),
    ],
)
def test_content_negotiation(
    served: Served, content_type: str, accept: str | None, returned: str
) -> None:
    answer = post(served, BODY, content_type, accept)
    assert answer.status_code == 200 and answer.headers["content-type"] == returned
    if returned == "application/msgpack":
        result = msgpack.unpackb(answer.content)
        assert len(result["data"]) == 4 * result["n_frames"] * result["n_channels"]
    else:
        assert len(answer.json()["data"]) == FRAMES


def test_audio_rides_along_for_audio_engines(served: Served) -> None:
    pcm = (np.arange(1200, dtype="<i2") % 300 * 50).astype("<i2").tobytes()
    body = {
        **BODY,
        "engine": "anime-graph",
        "channels": ["jawOpen"],
        "audio": {"sample_rate": 16000, "pcm16": base64.b64encode(pcm).decode()},
    }
    answer = post(served, body)
    assert answer.status_code == 200, answer.text
    assert np.array(answer.json()["data"]).shape == (FRAMES, 1)
    packed = post(
        served,
        {**body, "audio": {"sample_rate": 16000, "pcm16": pcm}},
        "application/msgpack",
        "application/json",
    )
    assert packed.json()["data"] == answer.json()["data"]


@pytest.mark.parametrize(
    ("body", "content_type", "accept", "status", "code", "text"),
    [
        ("{", "application/json", None, 400, "malformed", "not valid json"),
        ({**BODY, "speed": 2}, "application/json", None, 400, "invalid_message", "speed"),
        (
            {k: v for k, v in BODY.items() if k != "items"},
            "application/json",
            None,
            400,
            "invalid_message",
            "items",
        ),
        (
            {**BODY, "items": [ITEMS[1], ITEMS[0]]},
            "application/json",
            None,
            400,
            "non_monotonic_times",
            "items[1].start",
        ),
        (
            {**BODY, "audio": {"sample_rate": 16000, "pcm16": "AAA"}},
            "application/json",
            None,
            400,
            "invalid_audio",
            "audio.pcm16",
        ),
        ({**BODY, "engine": "nope"}, "application/json", None, 404, "unknown_engine", "engine"),
        (
            {**BODY, "engine": "nope"},
            "application/json",
            "text/csv",
            404,
            "unknown_engine",
            "engine",
        ),
        (
            {**BODY, "options": {"bogus": 1}},
            "application/json",
            None,
            422,
            "invalid_request",
            "options.bogus: unknown option(s) bogus for engine viseme-lerp; "
            "known options: mode, lead_ms",
        ),
        (
            {**BODY, "engine": "anime-graph", "options": {"max_jumps": 2, "smooth": False}},
            "application/json",
            None,
            422,
            "invalid_request",
            "unknown option(s) max_jumps for engine anime-graph; known options: graph, search, "
            "pq_window, pq_advance, blend, smooth, match_emotion, max_tile, pq_budget_s, causal, "
            "lead_ms",
        ),
        (
            {**BODY, "character": "x"},
            "application/json",
            None,
            404,
            "unknown_character",
            "character",
        ),
        (
            {**BODY, "items": [{"phoneme": "XQ", "start": 0, "end": 1}]},
            "application/json",
            None,
            422,
            "unknown_phoneme",
            "items[0].phoneme",
        ),
        (
            {**BODY, "channels": ["nose"]},
            "application/json",
            None,
            422,
            "unknown_channel",
            "channels[0]",
        ),
        (BODY, "text/plain", None, 415, "unsupported_media_type", "Content-Type"),
        (BODY, "application/json", "text/html", 406, "not_acceptable", "Accept"),
        (
            {
                **BODY,
                "items": [
                    {"phoneme": "AA", "start": i / 10, "end": (i + 1) / 10} for i in range(100)
                ],
            },
            "application/json",
            None,
            413,
            "message_too_large",
            "4096 bytes",
        ),
    ],
)
def test_errors_have_a_status_code_and_a_located_message(
    served: Served,
    body: Any,
    content_type: str,
    accept: str | None,
    status: int,
    code: str,
    text: str,
) -> None:
    answer = post(served, body, content_type, accept)
    assert answer.status_code == status
    error = answer.json()["error"]
    assert error["code"] == code and text in error["message"]


def test_csv_for_accept_text_csv_holds_the_frames_of_the_json_answer(served: Served) -> None:
    answer = post(served, BODY, accept="text/csv")
    assert answer.status_code == 200
    assert answer.headers["content-type"].split(";")[0] == "text/csv"
    rows = list(csv.reader(io.StringIO(answer.text)))
    as_json = post(served, BODY).json()
    assert rows[0] == ["time", *as_json["channels"]]
    assert len(rows) == 1 + FRAMES
    times = [float(row[0]) for row in rows[1:]]
    assert times == [round(index / 50, 6) for index in range(FRAMES)]
    values = np.array([[float(cell) for cell in row[1:]] for row in rows[1:]])
    np.testing.assert_allclose(values, np.array(as_json["data"]), atol=5e-7)
    assert all(len(cell.split(".")[1]) == 6 for cell in rows[5])


def test_preston_blair_mouth_shapes_as_csv(served: Served) -> None:
    body = {**BODY, "output": {"visemes": "preston-blair"}}
    answer = post(served, body, accept="text/csv")
    assert answer.status_code == 200, answer.text
    rows = list(csv.reader(io.StringIO(answer.text)))
    assert rows[0] == ["time", "A", "B", "C", "D", "E", "F", "G", "H", "X"]
    weights = np.array([[float(cell) for cell in row[1:]] for row in rows[1:]])
    np.testing.assert_allclose(weights.sum(axis=1), 1.0, atol=1e-5)
    assert weights.min() >= 0.0
    # At the centre of AY (0.2 s, frame 10) the mouth is wide open: shape D.
    assert rows[0][1 + int(np.argmax(weights[10]))] == "D"


OVERFLOW = "<overflow>"  # stands for a number beyond the double range; JSON reads infinity


@pytest.mark.parametrize(
    ("body", "code", "where"),
    [
        ({**BODY, "items": [{**ITEMS[0], "end": "-" + OVERFLOW}]}, "invalid_times", "items[0].end"),
        ({**BODY, "items": [{**ITEMS[0], "start": OVERFLOW}]}, "invalid_times", "items[0].start"),
        ({**BODY, "options": {"x": OVERFLOW}}, "invalid_message", "options.x"),
        ({**BODY, "options": {"x": [{"y": "-" + OVERFLOW}]}}, "invalid_message", "options.x"),
        ({**BODY, "fps": OVERFLOW}, "invalid_message", "fps"),
        ({**BODY, "latency_budget_ms": OVERFLOW}, "invalid_message", "latency_budget_ms"),
        (
            {**BODY, "output": {"transforms": {"jawOpen": {"multiplier": OVERFLOW}}}},
            "invalid_message",
            "multiplier",
        ),
    ],
)
@pytest.mark.parametrize("text", ["1e999", "1e400"])
def test_a_number_that_overflows_is_a_400_with_the_error_body(
    served: Served, body: dict[str, Any], code: str, where: str, text: str
) -> None:
    encoded = json.dumps(body).replace(f'"-{OVERFLOW}"', f"-{text}").replace(f'"{OVERFLOW}"', text)
    assert OVERFLOW not in encoded and text in encoded
    answer = post(served, encoded)
    assert (answer.status_code, answer.headers["content-type"]) == (400, "application/json")
    error = answer.json()["error"]
    assert error["code"] == code and where in error["message"] and "finite" in error["message"]


@pytest.mark.parametrize("value", [float("inf"), float("-inf"), float("nan")])
def test_msgpack_infinity_and_nan_are_a_400(served: Served, value: float) -> None:
    for body in (
        {**BODY, "options": {"x": value}},
        {**BODY, "items": [{**ITEMS[0], "end": value}]},
        {**BODY, "fps": value},
    ):
        answer = post(served, body, "application/msgpack")
        assert answer.status_code == 400
        error = msgpack.unpackb(answer.content)["error"]
        assert error["code"] in ("invalid_message", "invalid_times")
        assert "finite" in error["message"]


@pytest.mark.parametrize("fps", [1e-308, 0.5, 0.999])
def test_fps_below_one_is_refused(served: Served, fps: float) -> None:
    answer = post(served, {**BODY, "fps": fps})
    assert answer.status_code == 400
    error = answer.json()["error"]
    assert error["code"] == "invalid_message" and error["message"].startswith("fps: must be >= 1")


@pytest.mark.parametrize(("fps", "frames"), [(1, 3 + 1), (1.5, 4 + 1)])
def test_the_lowest_frame_rates_synthesize(served: Served, fps: float, frames: int) -> None:
    # Frames i with i / fps <= 2 s: 0, 1, 2 at 1 fps; 0 to 3 at 1.5 fps; then one frame
    # of return to rest (150 ms is less than a frame at either rate).
    items = [ITEMS[0], {**ITEMS[1], "end": 2.0}]
    answer = post(served, {**BODY, "fps": fps, "items": items})
    assert answer.status_code == 200
    assert answer.json()["n_frames"] == frames


def test_budget_infeasible_carries_the_smallest_feasible_budget(served: Served) -> None:
    answer = post(
        served, {**BODY, "latency_budget_ms": 1}, "application/json", "application/msgpack"
    )
    assert answer.status_code == 422
    error = msgpack.unpackb(answer.content)["error"]
    # The causal rung waits for nothing, so its worst case is compute plus the 5 ms margin.
    assert error["code"] == "budget_infeasible" and error["details"]["min_budget_ms"] > 5


def test_openapi_documents_the_routes_and_every_reference_resolves(served: Served) -> None:
    document = httpx.get(f"{served.http}/openapi.json").json()
    operation = document["paths"]["/v1/synthesize"]["post"]
    assert set(operation["requestBody"]["content"]) == {"application/json", "application/msgpack"}
    assert {"/healthz", "/readyz", "/v1/engines", "/v1/characters", "/metrics"} <= set(
        document["paths"]
    )
    request = document["components"]["schemas"]["lipstream_SynthesizeRequest"]
    assert {"engine", "character", "items", "audio", "output"} <= set(request["properties"])

    def references(node: Any) -> Iterator[str]:
        if isinstance(node, dict):
            for key, value in node.items():
                if key == "$ref":
                    yield value
                else:
                    yield from references(value)
        elif isinstance(node, list):
            for item in node:
                yield from references(item)

    schemas = document["components"]["schemas"]
    for reference in references(document):
        assert reference.startswith("#/components/schemas/")
        assert reference.rsplit("/", 1)[1] in schemas, reference
    assert httpx.get(f"{served.http}/docs").status_code == 200


def test_health_readiness_and_listings(served: Served) -> None:
    assert httpx.get(f"{served.http}/healthz").json() == {"status": "ok"}
    assert httpx.get(f"{served.http}/readyz").json() == {
        "ready": True,
        "phase": "ready",
        "failed_models": [],
    }
    characters = httpx.get(f"{served.http}/v1/characters").json()["characters"]
    assert characters == [{"name": "demo", "engines": sorted(engine_names())}]
