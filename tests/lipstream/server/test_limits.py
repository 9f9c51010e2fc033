"""Every protective limit of ``/v1/stream``, each against a real server with a small setting."""

from __future__ import annotations

import json
import socket
import time
from pathlib import Path
from urllib.parse import urlsplit

import httpx
import msgpack
import pytest

from lipstream.config import ServerSettings
from lipstream_client import (
    Done,
    Encoding,
    End,
    ErrorMessage,
    Frames,
    Message,
    PhonemeItem,
    Phonemes,
    Ready,
    Start,
    encode,
)
from lipstream_client.messages import JsonValue
from tests.helpers import eventually, return_frames
from tests.lipstream.server.harness import Client, client, only_errors, serving

ITEMS = (PhonemeItem("HH", 0.0, 0.1), PhonemeItem("AY1", 0.1, 0.3))


def connection_error(messages: list[Message]) -> tuple[str, bool, str | None]:
    [error] = [m for m in messages if isinstance(m, ErrorMessage)]
    return error.code, error.fatal, error.id


def test_message_size_limit_closes_with_1009(lerp_dir: Path) -> None:
    with serving(lerp_dir, ServerSettings(max_message_bytes=2048)) as served:
        with client(served.ws, "json") as ws:
            ws.send_raw('{"v":1,"type":"end","id":"' + "x" * 100 + '"}')
            [unknown] = only_errors([ws.recv()])
            assert unknown.code == "unknown_request"
            ws.send_raw(" " * 3000)  # above the limit, below the WebSocket layer's 2x
            messages, code, reason = ws.closed()
        assert connection_error(messages) == ("message_too_large", True, None)
        assert (code, reason) == (1009, "message_too_large")
        with client(served.ws, "msgpack") as ws:
            ws.send_raw(b"\x00" * 5000)  # beyond 2x: the WebSocket layer closes by itself
            messages, code, _ = ws.closed()
        assert (messages, code) == ([], 1009)


def test_phonemes_per_request_limit_ends_only_that_request(lerp_dir: Path) -> None:
    with (
        serving(lerp_dir, ServerSettings(max_phonemes_per_request=3)) as served,
        client(served.ws) as ws,
    ):
        ws.send(
            Start("a", "viseme-lerp", "demo"),
            Phonemes("a", ITEMS),
            Phonemes("a", (PhonemeItem("M", 0.3, 0.4), PhonemeItem("AA", 0.4, 0.5))),
        )
        answers = ws.until_done("a")
        assert connection_error(answers) == ("too_many_phonemes", True, "a")
        ws.send(Start("b", "viseme-lerp", "demo"), Phonemes("b", ITEMS), End("b"))
        assert isinstance(ws.until_done("b")[-1], Done)


def test_session_cap_refuses_with_1013_and_frees_on_close(lerp_dir: Path) -> None:
    with serving(lerp_dir, ServerSettings(max_sessions=2)) as served:
        with client(served.ws) as first, client(served.ws) as second:
            for ws in (first, second):
                ws.send(Start("a", "viseme-lerp", "demo"))
                assert isinstance(ws.recv(), Ready)
            with client(served.ws) as third:
                messages, code, reason = third.closed()
            assert connection_error(messages) == ("server_busy", True, None)
            assert (code, reason) == (1013, "server_busy")
            assert httpx.get(f"{served.http}/healthz").status_code == 200
            metrics = httpx.get(f"{served.http}/metrics").text
            assert 'lipstream_busy_refusals_total{reason="sessions"} 1.0' in metrics
            assert 'reason="loop_busy"' not in metrics and 'reason="memory"' not in metrics
        eventually(
            lambda: "lipstream_sessions 0.0" in httpx.get(f"{served.http}/metrics").text,
            "the closed sessions are freed",
        )
        with client(served.ws) as again:
            again.send(Start("a", "viseme-lerp", "demo"))
            assert isinstance(again.recv(), Ready)


def test_message_rate_limit_closes_with_1008(lerp_dir: Path) -> None:
    with (
        serving(lerp_dir, ServerSettings(message_rate=2.0, message_burst=4)) as served,
        client(served.ws) as ws,
    ):
        for _ in range(6):
            ws.send(End("x"))
        messages, code, reason = ws.closed()
    assert [m.code for m in only_errors(messages)] == ["unknown_request"] * 4 + ["rate_limited"]
    assert (code, reason) == (1008, "rate_limited")


def test_idle_timeout_closes_with_1000_once_the_request_is_done(lerp_dir: Path) -> None:
    """The close an idle connection gets over a real socket. When it comes (not before the
    idle time after the last message, never while a request is active) is proved on virtual
    loop time in ``test_idle_timeout``."""
    with serving(lerp_dir, ServerSettings(idle_timeout_s=0.3)) as served:
        with client(served.ws) as ws:
            ws.send(Start("a", "viseme-lerp", "demo"), Phonemes("a", ITEMS), End("a"))
            answers = ws.until_done("a")
            messages, code, reason = ws.closed()
        assert isinstance(answers[-1], Done) and answers[-1].reason == "end"
        assert connection_error(messages) == ("idle_timeout", True, None)
        assert (code, reason) == (1000, "idle_timeout")


def test_bearer_token_is_required_when_configured(lerp_dir: Path) -> None:
    with serving(lerp_dir, ServerSettings(auth_tokens=("s3cret", "other"))) as served:
        with client(served.ws) as ws:
            messages, code, reason = ws.closed()
        assert connection_error(messages) == ("unauthorized", True, None)
        assert (code, reason) == (1008, "unauthorized")
        with client(served.ws, additional_headers={"Authorization": "Bearer wrong"}) as ws:
            assert ws.closed()[1] == 1008
        with client(served.ws, additional_headers={"Authorization": "Bearer s3cret"}) as ws:
            ws.send(Start("a", "viseme-lerp", "demo"))
            assert isinstance(ws.recv(), Ready)
        with client(served.ws + "?access_token=other") as ws:
            ws.send(Start("a", "viseme-lerp", "demo"))
            assert isinstance(ws.recv(), Ready)
        body = {
            "engine": "viseme-lerp",
            "character": "demo",
            "items": [{"phoneme": "AA", "start": 0, "end": 0.1}],
        }
        refused = httpx.post(f"{served.http}/v1/synthesize", json=body)
        assert refused.status_code == 401 and refused.headers["www-authenticate"] == "Bearer"
        assert refused.json()["error"]["code"] == "unauthorized"
        allowed = httpx.post(
            f"{served.http}/v1/synthesize", json=body, headers={"Authorization": "Bearer s3cret"}
        )
        assert allowed.status_code == 200


def test_origin_allow_list(lerp_dir: Path) -> None:
    settings = ServerSettings(allowed_origins=("https://game.example",))
    with serving(lerp_dir, settings) as served:
        with client(served.ws, origin="https://evil.example") as ws:
            messages, code, reason = ws.closed()
        assert connection_error(messages) == ("origin_not_allowed", True, None)
        assert (code, reason) == (1008, "origin_not_allowed")
        for origin in ("https://GAME.example", None):  # listed (any case), or no browser
            with client(served.ws, origin=origin) as ws:
                ws.send(Start("a", "viseme-lerp", "demo"))
                assert isinstance(ws.recv(), Ready)


def test_a_client_that_stops_reading_is_closed_as_a_slow_consumer(lerp_dir: Path) -> None:
    settings = ServerSettings(send_timeout_s=0.4, max_request_frames=200_000)
    with serving(lerp_dir, settings) as served:
        address = urlsplit(served.http)
        sock = socket.socket()
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        sock.connect((address.hostname, address.port))
        items = tuple(PhonemeItem(("AA", "M")[i % 2], i * 0.1, (i + 1) * 0.1) for i in range(900))
        with client(served.ws, sock=sock, max_queue=1) as ws:
            ws.send(Start("a", "viseme-lerp", "demo", fps=1000))
            assert isinstance(ws.recv(), Ready)
            ws.send(Phonemes("a", items), End("a"))  # 90 s at 1000 fps: about 10 MB of frames
            time.sleep(1.0)  # not reading: the server's send deadline passes
            messages, code, reason = ws.closed(timeout=10)
    assert (code, reason) == (1008, "slow_consumer")
    blocks = [m for m in messages if isinstance(m, Frames)]
    assert not any(isinstance(m, Done) for m in messages)
    assert [block.seq for block in blocks] == list(range(len(blocks)))  # no silent gap
    assert 0 < sum(block.n_frames for block in blocks) < 90_001


@pytest.mark.parametrize("payload", [encode(Start("a", "viseme-lerp", "demo"), "msgpack")])
def test_limits_do_not_touch_well_behaved_clients(lerp_dir: Path, payload: bytes) -> None:
    settings = ServerSettings(
        max_message_bytes=2048, message_rate=50.0, message_burst=10, idle_timeout_s=5.0
    )
    with serving(lerp_dir, settings) as served, client(served.ws) as ws:
        ws.send_raw(payload)
        ws.send(Phonemes("a", ITEMS), End("a"))
        answers = ws.until_done("a")
    assert isinstance(answers[0], Ready) and isinstance(answers[-1], Done)


def request_error(answers: list[Message]) -> tuple[str, bool, str | None, dict[str, JsonValue]]:
    [error] = [m for m in answers if isinstance(m, ErrorMessage)]
    return error.code, error.fatal, error.id, dict(error.details or {})


def test_output_per_request_and_per_connection_is_limited(lerp_dir: Path) -> None:
    # At 60 fps, phonemes to t s commit floor(60 t) + 1 frames of the demo's 28 channels.
    settings = ServerSettings(max_request_values=2000, max_session_values=3000)
    with serving(lerp_dir, settings) as served, client(served.ws) as ws:
        ws.send(Start("a", "viseme-lerp", "demo"))
        ready = ws.recv()
        assert isinstance(ready, Ready) and len(ready.channels) == 28
        ws.send(Phonemes("a", (PhonemeItem("AA", 0.0, 1.0),)))  # 61 × 28 = 1708 values
        ws.send(Phonemes("a", (PhonemeItem("M", 1.0, 2.0),)))  # 121 × 28 = 3388 values
        answers = ws.until_done("a")
        assert request_error(answers) == (
            "output_too_large",
            True,
            "a",
            {"max_request_values": 2000, "values": 3388},
        )
        ws.send(Start("b", "viseme-lerp", "demo"), Start("c", "viseme-lerp", "demo"))
        ws.send(Phonemes("b", (PhonemeItem("AA", 0.0, 1.0),)))  # 1708 values
        ws.send(Phonemes("c", (PhonemeItem("AA", 0.0, 0.5),)))  # 31 × 28 = 868: 2576 in all
        ws.send(Phonemes("c", (PhonemeItem("M", 0.5, 1.0),)))  # 1708 + 1708 = 3416 > 3000
        answers = ws.until_done("c")
        assert request_error(answers) == (
            "output_too_large",
            True,
            "c",
            {"max_session_values": 3000, "values": 3416},
        )
        ws.send(End("b"))
        assert isinstance(ws.until_done("b")[-1], Done)
        # b's output is no longer held: a new request may take as much.
        ws.send(Start("d", "viseme-lerp", "demo"), Phonemes("d", (PhonemeItem("AA", 0, 1.0),)))
        ws.send(End("d"))
        done = ws.until_done("d")[-1]
        assert isinstance(done, Done) and done.stats.frames == 61 + return_frames(60.0)


def pending(ws: Client, wait_s: float) -> list[Message]:
    """The messages that arrive within ``wait_s``."""
    messages: list[Message] = []
    deadline = time.monotonic() + wait_s
    while (left := deadline - time.monotonic()) > 0:
        try:
            messages.append(ws.recv(timeout=left))
        except TimeoutError:
            break
    return messages


def test_a_request_without_messages_times_out_while_others_go_on(lerp_dir: Path) -> None:
    with serving(lerp_dir, ServerSettings(request_timeout_s=0.5)) as served:
        with client(served.ws) as ws:
            ws.send(Start("quiet", "viseme-lerp", "demo"), Start("busy", "viseme-lerp", "demo"))
            # busy sends a phoneme every 0.1 s until quiet has timed out (at most 5 s).
            end = 0.0
            errors: list[ErrorMessage] = []
            for _ in range(50):
                ws.send(Phonemes("busy", (PhonemeItem("AA", end, end + 0.1),)))
                end += 0.1
                errors += [m for m in pending(ws, 0.1) if isinstance(m, ErrorMessage)]
                if errors:
                    break
            assert [(e.code, e.id, e.fatal, e.details) for e in errors] == [
                ("request_timeout", "quiet", True, {"request_timeout_s": 0.5})
            ]
            ws.send(End("busy"))
            assert isinstance(ws.until_done("busy")[-1], Done)
            # A request started later times out in its turn.
            ws.send(Start("late", "viseme-lerp", "demo"))
            answers = ws.until_done("late")
        assert request_error(answers)[:3] == ("request_timeout", True, "late")


@pytest.mark.parametrize("fps", [1e-308, 0.5])
@pytest.mark.parametrize("encoding", ["msgpack", "json"])
def test_fps_below_one_is_refused_before_ready(
    lerp_dir: Path, fps: float, encoding: Encoding
) -> None:
    start = {"v": 1, "type": "start", "id": "a", "engine": "viseme-lerp", "character": "demo"}
    payload = {**start, "fps": fps}
    wire = msgpack.packb(payload) if encoding == "msgpack" else json.dumps(payload)
    with serving(lerp_dir) as served, client(served.ws, encoding) as ws:
        ws.send_raw(wire)
        error = ws.recv()
        assert isinstance(error, ErrorMessage)
        assert (error.code, error.id, error.fatal) == ("invalid_message", "a", True)
        assert error.message.startswith("fps: must be >= 1")
        ws.send(Start("b", "viseme-lerp", "demo", fps=1.0), Phonemes("b", ITEMS), End("b"))
        answers = ws.until_done("b")
    assert isinstance(answers[0], Ready) and answers[0].fps == 1.0
    # Frame 0, then the return to rest: 150 ms at 1 fps is one frame.
    assert isinstance(answers[-1], Done) and answers[-1].stats.frames == 1 + 1


def test_an_utterance_longer_than_the_limit_is_refused(lerp_dir: Path) -> None:
    with serving(lerp_dir, ServerSettings(max_request_s=2.0)) as served, client(served.ws) as ws:
        ws.send(Start("a", "viseme-lerp", "demo", fps=1.0))
        ws.send(Phonemes("a", (PhonemeItem("AA", 0.0, 2.0), PhonemeItem("M", 2.0, 2.5))))
        answers = ws.until_done("a")
    assert isinstance(answers[0], Ready)
    assert request_error(answers) == ("invalid_times", True, "a", {"max_request_s": 2.0})
