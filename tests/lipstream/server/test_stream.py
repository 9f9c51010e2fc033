"""``/v1/stream`` end to end: a real uvicorn server on loopback and the real websockets client."""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import msgpack
import numpy as np
import pytest
from websockets.exceptions import InvalidStatus

from lipstream.config import ServerSettings
from lipstream.server.catalog import Catalog
from lipstream_client import (
    AudioChunk,
    Cancel,
    ChannelTransform,
    Done,
    Encoding,
    End,
    ErrorMessage,
    Frames,
    Interrupt,
    Message,
    OutputProfile,
    PhonemeItem,
    Phonemes,
    Ready,
    Start,
    encode,
)
from tests.helpers import return_frames
from tests.lipstream.server.harness import Served, client, frame_rows, only_errors, serving

SPANS = [
    ("sil", 0.0, 0.05),
    ("HH", 0.05, 0.12),
    ("AY1", 0.12, 0.31),
    ("M", 0.31, 0.4),
    ("sil", 0.4, 0.5),
]
ITEMS = tuple(PhonemeItem(label, start, end) for label, start, end in SPANS)
PROFILE = OutputProfile(
    naming="livelink",
    channels=("JawOpen", "MouthClose", "MouthFunnel"),
    transforms={"JawOpen": ChannelTransform(1.5, 0.1, (0.0, 0.9))},
)


@pytest.fixture(scope="module")
def served(all_models_dir: Path) -> Iterator[Served]:
    with serving(all_models_dir, ServerSettings()) as running:
        yield running


def rows_of(messages: list[Message], identifier: str) -> np.ndarray:
    rows = frame_rows([m for m in messages if getattr(m, "id", None) == identifier])
    return np.array([rows[index] for index in sorted(rows)], dtype=np.float32)


def rest_frames(
    served: Served, body: dict[str, Any], encoding: Encoding
) -> tuple[np.ndarray, dict[str, Any]]:
    if encoding == "msgpack":
        answer = httpx.post(
            f"{served.http}/v1/synthesize",
            content=msgpack.packb(body),
            headers={"Content-Type": "application/msgpack", "Accept": "application/msgpack"},
        )
        assert answer.status_code == 200, answer.content
        result: dict[str, Any] = msgpack.unpackb(answer.content)
        frames = np.frombuffer(result["data"], "<f4").reshape(-1, result["n_channels"])
    else:
        answer = httpx.post(f"{served.http}/v1/synthesize", json=body)
        assert answer.status_code == 200, answer.text
        result = answer.json()
        frames = np.array(result["data"], dtype=np.float32)
    return frames, result


@pytest.mark.parametrize("encoding", ["msgpack", "json"])
def test_every_message_type_round_trips_in_both_encodings(
    served: Served, catalog: Catalog, encoding: Encoding
) -> None:
    with client(served.ws, encoding) as ws:
        assert ws.connection.subprotocol == f"lipstream.v1.{encoding}"
        ws.send(
            Start("a", "viseme-lerp", "demo", fps=60, output=PROFILE, emotion="happy"),
            Phonemes("a", ITEMS[:2]),
            Phonemes("a", ITEMS[2:]),
            End("a"),
        )
        ended = ws.until_done("a")
        ws.send(
            Start("b", "anime-graph", "demo", channels=("jawOpen",)),
            AudioChunk("b", 16000, (np.arange(800, dtype="<i2") * 7).tobytes()),
            Phonemes("b", ITEMS),
            Cancel("b"),
        )
        cancelled = ws.until_done("b")
        ws.send(
            Start("c", "viseme-lerp", "demo", fps=100),
            Phonemes("c", ITEMS),
            Interrupt("c", 0.2, 30.0),
        )
        interrupted = ws.until_done("c")
        ws.send(End("nobody"))
        error = ws.recv()
    ready = ended[0]
    assert isinstance(ready, Ready) and ready.channels == PROFILE.channels
    assert isinstance(ended[-1], Done) and ended[-1].reason == "end"
    assert ended[-1].stats.first_frame_latency_ms is not None
    model = catalog.model("viseme-lerp", "demo")
    offline = model.synthesize(SPANS, fps=60, emotion="happy").frames[:, :3].astype(np.float64)
    offline[:, 0] = np.clip(offline[:, 0] * 1.5 + 0.1, 0.0, 0.9)
    np.testing.assert_array_equal(
        rows_of(ended, "a")[: -return_frames(60)], offline.astype(np.float32)
    )
    assert isinstance(cancelled[-1], Done) and cancelled[-1].reason == "cancel"
    assert isinstance(interrupted[-1], Done) and interrupted[-1].reason == "interrupt"
    assert interrupted[-1].stats.frames == 24  # frames 0..19 stand, 20..23 return to rest
    assert isinstance(error, ErrorMessage)
    assert (error.code, error.id, error.fatal) == ("unknown_request", "nobody", False)


def test_requests_multiplexed_on_one_connection_stay_independent(
    served: Served, catalog: Catalog
) -> None:
    utterances = {
        "npc-1": SPANS,
        "npc-2": [("S", 0.0, 0.2), ("OW1", 0.2, 0.6)],
        "npc-3": [("F", 0.1, 0.3), ("IY1", 0.3, 0.45)],
    }
    with client(served.ws, "json") as ws:
        for identifier in utterances:
            ws.send(Start(identifier, "viseme-lerp", "demo", fps=30))
        for index in range(2):  # interleave the phonemes of every request
            for identifier, spans in utterances.items():
                if index < len(spans):
                    ws.send(Phonemes(identifier, (PhonemeItem(*spans[index]),)))
        for identifier, spans in utterances.items():
            ws.send(
                Phonemes(identifier, tuple(PhonemeItem(*span) for span in spans[2:]))
                if len(spans) > 2
                else End(identifier)
            )
            if len(spans) > 2:
                ws.send(End(identifier))
        messages: list[Message] = []
        while sum(isinstance(m, Done) for m in messages) < 3:
            messages.append(ws.recv())
    model = catalog.model("viseme-lerp", "demo")
    for identifier, spans in utterances.items():
        np.testing.assert_array_equal(
            rows_of(messages, identifier)[: -return_frames(30)],
            model.synthesize(spans, fps=30).frames,
        )


@pytest.mark.parametrize(
    ("start", "encoding"),
    [
        (Start("r", "viseme-lerp", "demo", fps=60, output=PROFILE), "msgpack"),
        (
            Start(
                "r",
                "anime-graph",
                "demo",
                fps=30,
                output=OutputProfile(visemes="oculus15"),
                latency_budget_ms=5000,
            ),
            "json",
        ),
    ],
)
def test_streamed_frames_equal_post_synthesize(
    served: Served, start: Start, encoding: Encoding
) -> None:
    with client(served.ws, encoding) as ws:
        ws.send(start, *(Phonemes("r", (item,)) for item in ITEMS), End("r"))
        streamed = ws.until_done("r")
    body = {
        "engine": start.engine,
        "character": start.character,
        "fps": start.fps,
        "items": [{"phoneme": i.phoneme, "start": i.start, "end": i.end} for i in ITEMS],
        "output": _output_json(start.output),
        "latency_budget_ms": start.latency_budget_ms,
    }
    frames, result = rest_frames(served, {k: v for k, v in body.items() if v is not None}, encoding)
    assert frames.tobytes() == rows_of(streamed, "r").tobytes()
    ready = streamed[0]
    assert isinstance(ready, Ready)
    assert (result["channels"], result["fidelity"], result["lookahead_ms"]) == (
        list(ready.channels),
        ready.fidelity,
        ready.lookahead_ms,
    )
    assert result["stats"]["frames"] == len(frames)
    assert len(frames) == int(0.5 * start.fps) + 1 + return_frames(start.fps)


def _output_json(profile: OutputProfile | None) -> dict[str, Any] | None:
    if profile is None:
        return None
    message = encode(Start("x", "e", "c", output=profile), "json")
    output: dict[str, Any] = json.loads(message)["output"]
    return output


def test_subprotocol_negotiation_and_no_compression(served: Served) -> None:
    with client(served.ws, "msgpack", subprotocols=None, compression="deflate") as ws:
        assert ws.connection.subprotocol is None  # none offered: msgpack
        response = ws.connection.response
        assert response is not None
        assert response.headers.get("Sec-WebSocket-Extensions") is None
        ws.send(Start("a", "viseme-lerp", "demo"))
        assert isinstance(ws.recv(), Ready)
    with client(
        served.ws,
        "json",
        subprotocols=["lipstream.v2.json", "lipstream.v1.json", "lipstream.v1.msgpack"],
    ) as ws:
        assert ws.connection.subprotocol == "lipstream.v1.json"
    with (
        pytest.raises(InvalidStatus) as refused,
        client(served.ws, "json", subprotocols=["lipstream.v2.json"]),
    ):
        pass
    assert refused.value.response.status_code == 403


def test_bad_input_gets_errors_and_the_connection_keeps_serving(served: Served) -> None:
    with client(served.ws, "msgpack") as ws:
        ws.send_raw(b"\x93\x01")  # truncated msgpack
        ws.send_raw('{"v": 1, "type": "end", "id": "a"}')  # JSON text on msgpack
        ws.send_raw(encode(Start("a", "viseme-lerp", "demo"), "msgpack") + b"\x00")  # trailing
        codes = [ws.recv() for _ in range(3)]
        assert [(m.code, m.fatal) for m in only_errors(codes)] == [
            ("malformed", False),
            ("malformed", False),
            ("malformed", False),
        ]
        ws.send(Start("a", "viseme-lerp", "demo"), Phonemes("a", ITEMS), End("a"))
        assert isinstance(ws.until_done("a")[-1], Done)


def test_health_answers_while_a_long_synthesis_runs(served: Served) -> None:
    spans = [
        (("AA1", "M", "S", "IY1")[index % 4], index * 0.08, (index + 1) * 0.08)
        for index in range(10_000)
    ]  # the default per-request limit
    items = tuple(PhonemeItem(*span) for span in spans)
    streamed = threading.Event()
    done: list[Message] = []

    def stream() -> None:
        with client(served.ws, "msgpack") as ws:
            ws.send(Start("long", "anime-graph", "demo", fps=120))
            ws.send(Phonemes("long", items), End("long"))
            done.extend(ws.until_done("long", limit=100_000)[-1:])
        streamed.set()

    worker = threading.Thread(target=stream)
    worker.start()
    answered_during = 0
    with httpx.Client() as http:
        while not streamed.is_set() and worker.is_alive():
            assert http.get(f"{served.http}/healthz", timeout=30.0).status_code == 200
            answered_during += not streamed.is_set()
            time.sleep(0.01)
    worker.join()
    # An event loop blocked by the synthesis would answer the health checks only after the
    # request's ``done``; answered in between, they outnumber any race at the end. (The
    # health latency under load is measured by ``lipstream loadtest soak``.)
    assert len(done) == 1 and isinstance(done[0], Done), done
    assert done[0].reason == "end" and done[0].stats.frames > 0
    assert answered_during >= 5


def test_metrics_count_sessions_frames_latency_and_errors(served: Served) -> None:
    with client(served.ws, "msgpack") as ws:
        ws.send(Start("m", "viseme-lerp", "demo"), Phonemes("m", ITEMS), End("m"))
        frames = sum(m.n_frames for m in ws.until_done("m") if isinstance(m, Frames))
        ws.send(Start("m", "viseme-lerp", "demo", emotion="bored"))
        [refused] = only_errors([ws.recv()])
        assert refused.code == "unknown_emotion"
        text = httpx.get(f"{served.http}/metrics").text
    assert "lipstream_sessions 1.0" in text
    assert 'lipstream_errors_total{code="unknown_emotion"}' in text
    assert 'lipstream_first_frame_latency_seconds_count{engine="viseme-lerp"}' in text
    assert 'lipstream_frame_lag_seconds_bucket{engine="viseme-lerp",le="+Inf"}' in text
    total = next(
        line
        for line in text.splitlines()
        if line.startswith('lipstream_frames_total{engine="viseme-lerp"}')
    )
    assert float(total.split()[-1]) >= frames == 31 + return_frames(60)


@pytest.mark.parametrize(
    ("engine", "options", "known"),
    [
        ("viseme-lerp", {"bogus": 1}, "mode, lead_ms"),
        ("anime-graph", {"bogus": 1}, "graph, search, pq_window"),
    ],
)
def test_unknown_engine_options_get_a_coded_error_listing_the_known_ones(
    served: Served, engine: str, options: dict[str, int], known: str
) -> None:
    with client(served.ws, "json") as ws:
        ws.send(Start("o", engine, "demo", options=options))
        error = ws.recv()
        ws.send(Start("p", engine, "demo"), Phonemes("p", ITEMS), End("p"))
        after = ws.until_done("p")
    assert isinstance(error, ErrorMessage)
    assert (error.code, error.id, error.fatal) == ("invalid_request", "o", True)
    assert error.message.startswith(f"options.bogus: unknown option(s) bogus for engine {engine}")
    assert f"; known options: {known}" in error.message
    assert isinstance(after[-1], Done)  # the connection serves the next request
