"""Connections before their request head, against a real server: the head deadline, the
connection cap, and ``/healthz`` past it."""

from __future__ import annotations

import re
import socket
from contextlib import ExitStack
from pathlib import Path
from urllib.parse import urlsplit

import httpx
import pytest
from websockets.exceptions import InvalidStatus

from lipstream.config import ServerSettings
from lipstream.server.handshake import PROBE_LANE
from lipstream_client import Ready, Start
from tests.helpers import eventually
from tests.lipstream.server.harness import client, serving

EOF_WAIT_S = 15.0  # far above every head deadline used here


def raw_socket(url: str) -> socket.socket:
    parts = urlsplit(url)
    sock = socket.create_connection((parts.hostname, parts.port), timeout=EOF_WAIT_S)
    sock.settimeout(EOF_WAIT_S)
    return sock


def read_until_closed(sock: socket.socket) -> bytes:
    """Everything the server sends until it closes; socket.timeout if it never does."""
    received = b""
    try:
        while chunk := sock.recv(65536):
            received += chunk
    except ConnectionResetError:
        pass
    return received


def refused_count(base: str, code: str) -> float:
    """``lipstream_connections_refused_total`` for ``code`` (0 before the first)."""
    text = httpx.get(f"{base}/metrics").text
    match = re.search(rf'^lipstream_connections_refused_total{{code="{code}"}} (\S+)$', text, re.M)
    return float(match.group(1)) if match else 0.0


def test_a_silent_connection_is_closed_after_the_head_deadline(lerp_dir: Path) -> None:
    with serving(lerp_dir, ServerSettings(handshake_timeout_s=0.3)) as served:
        with raw_socket(served.http) as silent:
            assert read_until_closed(silent) == b""
        assert httpx.get(f"{served.http}/healthz").json() == {"status": "ok"}
        assert refused_count(served.http, "handshake_timeout") >= 1


def test_a_partial_request_head_is_closed_after_the_head_deadline(lerp_dir: Path) -> None:
    with serving(lerp_dir, ServerSettings(handshake_timeout_s=0.3)) as served:
        with raw_socket(served.http) as partial:
            partial.sendall(b"GET /v1/engines HTTP/1.1\r\nHost: test\r\nX-Slow: ")
            assert read_until_closed(partial) == b""


def test_the_deadline_starts_again_after_each_response(lerp_dir: Path) -> None:
    """A keep-alive connection that sends half of its second request head is closed too
    (uvicorn's keep-alive timer stops at the first byte of it)."""
    settings = ServerSettings(handshake_timeout_s=0.3)
    with serving(lerp_dir, settings) as served, raw_socket(served.http) as sock:
        sock.sendall(b"GET /healthz HTTP/1.1\r\nHost: test\r\n\r\n")
        first = b""
        while not first.endswith(b'{"status":"ok"}'):
            chunk = sock.recv(65536)
            assert chunk, "the first request must be answered"
            first += chunk
        assert first.startswith(b"HTTP/1.1 200")
        sock.sendall(b"GET /healthz HTTP/1.1\r\nHo")
        assert read_until_closed(sock) == b""


def test_a_session_outlives_the_head_deadline(lerp_dir: Path) -> None:
    """The deadline ends with the upgrade: a WebSocket idle for longer still works."""
    settings = ServerSettings(handshake_timeout_s=0.2)
    with serving(lerp_dir, settings) as served, client(served.ws) as ws:
        with pytest.raises(TimeoutError):
            ws.recv(timeout=0.6)  # three deadlines pass with nothing said
        ws.send(Start("a", "viseme-lerp", "demo"))
        assert isinstance(ws.recv(), Ready)


def test_past_the_connection_cap_only_healthz_is_answered(lerp_dir: Path) -> None:
    with serving(lerp_dir, ServerSettings(max_connections=2)) as served:
        with client(served.ws) as first, client(served.ws) as second:
            for ws in (first, second):
                ws.send(Start("a", "viseme-lerp", "demo"))
                assert isinstance(ws.recv(), Ready)
            refused = httpx.get(f"{served.http}/v1/engines")
            assert refused.status_code == 503
            assert refused.headers["retry-after"] == "1"
            assert refused.headers["connection"] == "close"
            assert httpx.get(f"{served.http}/healthz").json() == {"status": "ok"}
            with pytest.raises(InvalidStatus) as upgrade, client(served.ws):
                pass
            assert upgrade.value.response.status_code == 503
        eventually(  # the sessions' sockets close a moment after the client's
            lambda: httpx.get(f"{served.http}/v1/engines").status_code == 200,
            "the cap freed once the sessions closed",
        )
        assert refused_count(served.http, "too_many_connections") >= 2  # request, upgrade


def test_past_the_probe_lane_a_connection_is_refused_before_it_speaks(lerp_dir: Path) -> None:
    with serving(lerp_dir, ServerSettings(max_connections=1)) as served, client(served.ws):
        with ExitStack() as stack:
            sockets = [stack.enter_context(raw_socket(served.http)) for _ in range(PROBE_LANE + 8)]
            answers = [read_until_closed(sock) for sock in sockets]
        refused = [answer for answer in answers if answer]
        assert refused, "no connection beyond the probe lane was refused at once"
        for answer in refused:
            assert answer.startswith(b"HTTP/1.1 503 Service Unavailable\r\n")
            assert b"\r\nretry-after: 1\r\n" in answer
