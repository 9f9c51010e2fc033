"""Every protective limit of ``/v1/stream``, each against a real server with a small setting."""

from __future__ import annotations

import socket
import time
from pathlib import Path
from urllib.parse import urlsplit

import httpx
import pytest

from lipstream.config import ServerSettings
from lipstream_client import (
    Done,
    End,
    ErrorMessage,
    Frames,
    PhonemeItem,
    Phonemes,
    Ready,
    Start,
    encode,
)
from tests.lipstream.server.harness import client, serving

ITEMS = (PhonemeItem("HH", 0.0, 0.1), PhonemeItem("AY1", 0.1, 0.3))


def connection_error(messages: list) -> tuple[str, bool, str | None]:  # type: ignore[type-arg]
    [error] = [m for m in messages if isinstance(m, ErrorMessage)]
    return error.code, error.fatal, error.id


def test_message_size_limit_closes_with_1009(lerp_dir: Path) -> None:
    with serving(lerp_dir, ServerSettings(max_message_bytes=2048)) as served:
        with client(served.ws, "json") as ws:
            ws.send_raw('{"v":1,"type":"end","id":"' + "x" * 100 + '"}')
            assert ws.recv().code == "unknown_request"  # type: ignore[union-attr]
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
        deadline = time.monotonic() + 30
        while httpx.get(f"{served.http}/metrics").text.count("lipstream_sessions 0.0") == 0:
            assert time.monotonic() < deadline
            time.sleep(0.02)
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
    assert [m.code for m in messages] == ["unknown_request"] * 4 + ["rate_limited"]  # type: ignore[union-attr]
    assert (code, reason) == (1008, "rate_limited")


def test_idle_timeout_closes_with_1000_only_without_active_requests(lerp_dir: Path) -> None:
    with serving(lerp_dir, ServerSettings(idle_timeout_s=0.3)) as served:
        with client(served.ws) as ws:
            ws.send(Start("a", "viseme-lerp", "demo"))
            assert isinstance(ws.recv(), Ready)
            time.sleep(0.6)  # an active request keeps the connection
            ws.send(Phonemes("a", ITEMS), End("a"))
            assert isinstance(ws.until_done("a")[-1], Done)
            began = time.monotonic()
            messages, code, reason = ws.closed()
            waited = time.monotonic() - began
        assert connection_error(messages) == ("idle_timeout", True, None)
        assert (code, reason) == (1000, "idle_timeout")
        assert 0.2 < waited < 2.0


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
