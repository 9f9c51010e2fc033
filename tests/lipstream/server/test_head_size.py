"""Oversized request heads, against a real server: 431 and the connection closed, whatever the
size and however the head arrives, and the connection's slot freed."""

from __future__ import annotations

import socket
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from lipstream.config import ServerSettings
from lipstream_client import Ready, Start
from tests.lipstream.server.harness import Served, client, serving
from tests.lipstream.server.test_handshake import raw_socket, read_until_closed, refused_count

# The head deadline is far away, so a close can only come from the answer to the head.
LONG_DEADLINE = ServerSettings(handshake_timeout_s=600.0, max_connections=3)
SIZES = (10 * 1024, 16 * 1024, 64 * 1024, 1024 * 1024)


@pytest.fixture(scope="module")
def served(lerp_dir: Path) -> Iterator[Served]:
    with serving(lerp_dir, LONG_DEADLINE) as server:
        yield server


def upgrade_head(header_bytes: int) -> bytes:
    """A WebSocket upgrade for /v1/stream with one ``X-Big`` header line of ``header_bytes``."""
    return (
        b"GET /v1/stream HTTP/1.1\r\nHost: test\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
        b"Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n"
        + b"X-Big: "
        + b"a" * (header_bytes - len(b"X-Big: "))
        + b"\r\n\r\n"
    )


def send_head(sock: socket.socket, head: bytes) -> None:
    """Send ``head``; the server may answer and close before it has read all of it."""
    try:
        sock.sendall(head)
    except (BrokenPipeError, ConnectionResetError):
        pass


def assert_431(answer: bytes) -> None:
    assert answer.startswith(b"HTTP/1.1 431 "), answer[:200]
    assert b"\r\n\r\n" in answer


@pytest.mark.parametrize("size", SIZES)
def test_an_oversized_upgrade_header_gets_431_and_the_slot_is_freed(
    served: Served, size: int
) -> None:
    """More connections with big heads than the cap, one after the other: each is answered
    431 and closed, so the cap never fills, and then a session works."""
    before = refused_count(served.http, "head_too_large")
    attempts = LONG_DEADLINE.max_connections + 2
    for _ in range(attempts):
        with raw_socket(served.http) as sock:
            send_head(sock, upgrade_head(size))
            assert_431(read_until_closed(sock))
    with client(served.ws) as ws:
        ws.send(Start("a", "viseme-lerp", "demo"))
        assert isinstance(ws.recv(), Ready)
    assert httpx.get(f"{served.http}/v1/engines").status_code == 200
    assert refused_count(served.http, "head_too_large") == before + attempts


def test_an_oversized_head_in_small_pieces_gets_431(served: Served) -> None:
    """A head trickled in pieces is refused once it passes the limit, not at its end."""
    with raw_socket(served.http) as sock:
        head = upgrade_head(64 * 1024)
        sent = 0
        answer = b""
        sock.settimeout(0.05)
        while sent < len(head) - 4:  # never the head's end: the server must not wait for it
            try:
                sock.sendall(head[sent : sent + 1024])
            except (BrokenPipeError, ConnectionResetError):
                break
            sent += 1024
            try:
                answer = sock.recv(65536)
            except TimeoutError:
                continue
            break
        sock.settimeout(30)
        answer += read_until_closed(sock)
        assert_431(answer)
        assert sent < len(head) - 4


@pytest.mark.parametrize("path", ["/v1/engines", "/healthz"])
def test_an_oversized_plain_request_head_gets_431(served: Served, path: str) -> None:
    with raw_socket(served.http) as sock:
        head = f"GET {path} HTTP/1.1\r\nHost: test\r\nX-Big: ".encode()
        send_head(sock, head + b"a" * 32 * 1024 + b"\r\n\r\n")
        assert_431(read_until_closed(sock))


def test_a_head_under_the_limit_is_served(served: Served) -> None:
    """An 8,000-byte header line is within every limit: the upgrade completes."""
    with raw_socket(served.http) as sock:
        sock.sendall(upgrade_head(8000))
        answer = b""
        while b"\r\n\r\n" not in answer:
            chunk = sock.recv(65536)
            assert chunk, answer
            answer += chunk
        assert answer.startswith(b"HTTP/1.1 101 ")
