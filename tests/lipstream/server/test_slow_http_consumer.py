"""HTTP clients that stop reading are reset within a bound; slow readers and idle ones are not.

The clients are raw sockets on loopback. One posts a long utterance at a high
frame rate (a msgpack response of about 10 MB, beyond every buffer on the
way) from a socket with a small receive buffer and never reads: the server
must reset it within 2 × the send timeout of its buffers filling (the first
check after the buffer fills takes a baseline because the response's end may
have written, the second finds nothing taken), while other HTTP and
WebSocket clients are served. One reads a 4 MB response slowly but steadily,
over many send timeouts: it must get every byte, although the transport's
own buffer moves only in steps of about a megabyte, seconds apart. One keeps
its connection idle between requests for several send timeouts: nothing is
unsent, so it keeps its connection. Two more do the same with a streamed
response (a route the tests add), whose app writes part after part: the app
waiting for a drain that never comes is released by the reset, and a slow
reader, the app's writes in between notwithstanding, gets every byte. Last,
a WebSocket upgrade that follows a response still unread is judged by the
WebSocket's rules, not reset by the HTTP connection's watch.
"""

from __future__ import annotations

import asyncio
import base64
import json
import os
import socket
import time
from collections.abc import AsyncIterator, Iterator
from pathlib import Path
from urllib.parse import urlsplit

import httpx
import msgpack
import numpy as np
import pytest
from starlette.responses import StreamingResponse

from lipstream.config import ServerSettings
from lipstream.engines.base import Model
from lipstream.server.flush_watch import unsent_bytes
from lipstream_client import SUBPROTOCOL_MSGPACK, Done, End, PhonemeItem, Phonemes, Start
from tests.helpers import eventually, return_frames
from tests.lipstream.server.harness import Served, client, frame_rows, serving
from tests.lipstream.server.test_slow_consumer import (
    SPANS,
    TCP_STATES_GONE,
    read_until_closed,
    server_connection,
    server_socket_states,
)

SEND_TIMEOUT_S = 0.5
LONG_SPANS = [(("AA", "M")[i % 2], i * 0.1, (i + 1) * 0.1) for i in range(900)]
NEVER_READ_FPS = 1000  # 90 000 frames of 28 float32: about 10 MB
STEADY_FPS = 400  # 36 000 frames: about 4 MB
STEADY_CHUNK = 4096
STEADY_PAUSE_S = 0.005  # at most 800 kB/s: the transport's buffer then moves once in about
# 1.25 s, longer than 2 × SEND_TIMEOUT_S
SMALL_RECEIVE_BUFFER = 4096
UPGRADE_FPS = 100  # about 1 MB, all of it in the kernel's buffers
STREAM_CHUNK = bytes(range(256)) * 256  # 64 KiB
STREAM_CHUNKS = 32


@pytest.fixture(scope="module")
def served(lerp_dir: Path) -> Iterator[Served]:
    settings = ServerSettings(send_timeout_s=SEND_TIMEOUT_S, max_request_frames=200_000)
    with serving(lerp_dir, settings) as running:
        yield running


def synthesize_body(spans: list[tuple[str, float, float]], fps: int) -> bytes:
    items = [{"phoneme": phoneme, "start": start, "end": end} for phoneme, start, end in spans]
    return json.dumps(
        {"engine": "viseme-lerp", "character": "demo", "fps": fps, "items": items}
    ).encode()


def connect(served: Served, receive_buffer: int | None = None) -> socket.socket:
    address = urlsplit(served.http)
    sock = socket.socket()
    if receive_buffer is not None:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, receive_buffer)
    sock.settimeout(5.0)
    sock.connect((address.hostname, address.port))
    return sock


def send_request(sock: socket.socket, method: str, path: str, body: bytes = b"") -> None:
    head = (
        f"{method} {path} HTTP/1.1\r\nHost: lipstream\r\nAccept: application/msgpack\r\n"
        f"Content-Type: application/json\r\nContent-Length: {len(body)}\r\n\r\n"
    )
    sock.sendall(head.encode() + body)


class PacedReader:
    """A socket read ``chunk`` bytes at most at a time, ``pause_s`` before every read but
    the first."""

    def __init__(self, sock: socket.socket, pause_s: float, chunk: int) -> None:
        self.sock, self.pause_s, self.chunk = sock, pause_s, chunk
        self.buffer = b""
        self.reads = 0

    def _read(self, most: int) -> None:
        if self.reads:
            time.sleep(self.pause_s)
        self.reads += 1
        received = self.sock.recv(min(self.chunk, most))
        assert received, f"the server closed after {len(self.buffer)} buffered bytes"
        self.buffer += received

    def until(self, marker: bytes) -> bytes:
        """The bytes before ``marker``; both are consumed."""
        while marker not in self.buffer:
            self._read(self.chunk)
        found, _, self.buffer = self.buffer.partition(marker)
        return found

    def exactly(self, size: int) -> bytes:
        while len(self.buffer) < size:
            self._read(size - len(self.buffer))
        found, self.buffer = self.buffer[:size], self.buffer[size:]
        return found

    def response(self) -> tuple[int, bytes]:
        """Status and body of one response (Content-Length or chunked); what follows it
        stays in ``buffer``."""
        lines = self.until(b"\r\n\r\n").decode("latin-1").split("\r\n")
        headers = dict(line.lower().split(": ", 1) for line in lines[1:])
        status = int(lines[0].split()[1])
        if "content-length" in headers:
            return status, self.exactly(int(headers["content-length"]))
        assert headers.get("transfer-encoding") == "chunked", headers
        parts = []
        while size := int(self.until(b"\r\n").split(b";")[0], 16):
            parts.append(self.exactly(size))
            assert self.exactly(2) == b"\r\n"
        assert self.until(b"\r\n") == b"", "no trailers are sent"
        return status, b"".join(parts)


def read_response(
    sock: socket.socket, pause_s: float = 0.0, chunk: int = 1 << 16
) -> tuple[int, bytes]:
    """Status and body of one response, read ``chunk`` bytes at a time with ``pause_s``
    before each read but the first."""
    return PacedReader(sock, pause_s, chunk).response()


def paused_s(body: bytes) -> float:
    """The least time ``read_response`` with ``STEADY_PAUSE_S`` and ``STEADY_CHUNK`` spent
    pausing to read ``body``: a pause before each read, each read at most a chunk."""
    return (len(body) // STEADY_CHUNK - 1) * STEADY_PAUSE_S


def add_stream_route(served: Served, path: str, chunks: int | None) -> list[asyncio.Task[None]]:
    """A route streaming ``chunks`` × ``STREAM_CHUNK`` (forever if None), a part per send; the
    list gets the task serving each request."""
    tasks: list[asyncio.Task[None]] = []

    async def body() -> AsyncIterator[bytes]:
        sent = 0
        while chunks is None or sent < chunks:
            yield STREAM_CHUNK
            sent += 1
            await asyncio.sleep(0)  # as a real source would wait for its next part

    async def stream() -> StreamingResponse:
        task = asyncio.current_task()
        assert task is not None
        tasks.append(task)
        length = {} if chunks is None else {"content-length": str(chunks * len(STREAM_CHUNK))}
        return StreamingResponse(body(), headers=length, media_type="application/octet-stream")

    served.app.add_api_route(path, stream)
    return tasks


def response_frames(body: bytes) -> np.ndarray:
    result = msgpack.unpackb(body)
    return np.frombuffer(result["data"], "<f4").reshape(result["n_frames"], result["n_channels"])


def test_a_client_that_never_reads_its_response_is_reset_while_others_are_served(
    served: Served, trained_models: dict[str, Model]
) -> None:
    model = trained_models["viseme-lerp"]
    never = connect(served, SMALL_RECEIVE_BUFFER)
    server_port, client_port = never.getpeername()[1], never.getsockname()[1]
    send_request(never, "POST", "/v1/synthesize", synthesize_body(LONG_SPANS, NEVER_READ_FPS))
    connection = eventually(lambda: server_connection(served, client_port), "connected")
    transport = connection.transport  # type: ignore[attr-defined]  # uvicorn's protocol state
    eventually(lambda: transport.get_write_buffer_size() > 0, "the response stalls")

    short = synthesize_body(SPANS, 60)
    answer = httpx.post(
        f"{served.http}/v1/synthesize",
        content=short,
        timeout=5,
        headers={"Content-Type": "application/json"},
    )
    with client(served.ws) as other:
        other.send(
            Start("a", "viseme-lerp", "demo"),
            Phonemes("a", tuple(PhonemeItem(*span) for span in SPANS)),
            End("a"),
        )
        messages = other.until_done("a")
    served_meanwhile = server_connection(served, client_port) is not None

    eventually(lambda: server_connection(served, client_port) is None, "the socket is freed")
    states_after = server_socket_states(server_port, client_port)
    received, ending = read_until_closed(never)
    never.close()

    expected = model.synthesize(SPANS, fps=60).frames
    assert served_meanwhile, "the other clients finished after the stalled one was reset"
    assert answer.status_code == 200
    spoken = len(expected)
    data = answer.json()["data"]
    assert len(data) == spoken + return_frames(60)
    assert np.array(data[:spoken], np.float32).tobytes() == expected.tobytes()
    assert isinstance(messages[-1], Done) and messages[-1].reason == "end"
    rows = frame_rows(messages)
    assert sorted(rows) == list(range(spoken + return_frames(60)))
    np.testing.assert_array_equal(np.array([rows[i] for i in range(spoken)]), expected)

    # Judged by the send timeout (the checks a reset takes: test_flush_watch, by hand).
    assert connection.flush_watch.timeout_s == SEND_TIMEOUT_S  # type: ignore[attr-defined]  # uvicorn's protocol state
    # A reset: the server's end is gone from the kernel's table, not flushing in FIN_WAIT1 ...
    assert states_after <= TCP_STATES_GONE
    # ... and the client read only what its own small buffer held of ~10 MB, then ECONNRESET.
    assert ending == "reset"
    assert 0 < received < 1 << 18


def test_a_slow_but_steady_reader_gets_the_whole_response(
    served: Served, trained_models: dict[str, Model]
) -> None:
    sock = connect(served, SMALL_RECEIVE_BUFFER)
    send_request(sock, "POST", "/v1/synthesize", synthesize_body(LONG_SPANS, STEADY_FPS))
    status, body = read_response(sock, STEADY_PAUSE_S, STEADY_CHUNK)
    sock.close()

    assert status == 200
    assert len(body) > 4_000_000
    assert paused_s(body) > 6 * SEND_TIMEOUT_S  # the read spans many checks of the watch
    expected = trained_models["viseme-lerp"].synthesize(LONG_SPANS, fps=STEADY_FPS).frames
    frames = response_frames(body)
    assert len(frames) == len(expected) + return_frames(STEADY_FPS)
    np.testing.assert_array_equal(frames[: len(expected)], expected)


def test_an_idle_keep_alive_connection_is_kept(served: Served) -> None:
    sock = connect(served)
    client_port = sock.getsockname()[1]
    send_request(sock, "POST", "/v1/synthesize", synthesize_body(SPANS, 60))
    first, _ = read_response(sock)
    time.sleep(3 * SEND_TIMEOUT_S)
    still_open = server_connection(served, client_port) is not None
    send_request(sock, "GET", "/healthz")
    second, body = read_response(sock)
    sock.close()

    assert (first, second) == (200, 200)
    assert still_open
    assert json.loads(body) == {"status": "ok"}


def test_a_streamed_response_the_client_stops_reading_ends_the_apps_wait(served: Served) -> None:
    tasks = add_stream_route(served, "/test/endless", None)
    never = connect(served, SMALL_RECEIVE_BUFFER)
    client_port = never.getsockname()[1]
    send_request(never, "GET", "/test/endless")
    connection = eventually(lambda: server_connection(served, client_port), "connected")
    transport = connection.transport  # type: ignore[attr-defined]  # uvicorn's protocol state
    eventually(lambda: transport.get_write_buffer_size() > 0, "the response stalls")
    eventually(lambda: server_connection(served, client_port) is None, "the socket is freed")
    # The app waits for a drain that never comes (the buffer may fill, drain into the
    # kernel's growing buffer and fill again, each fill arming the watch anew) ...
    eventually(lambda: all(task.done() for task in tasks), "the app's task ends")
    received, ending = read_until_closed(never)
    never.close()

    # ... until the reset ends that wait: the endless body ends no other way.
    assert len(tasks) == 1
    assert ending == "reset" and 0 < received < 1 << 18


def test_a_slow_but_steady_reader_gets_a_whole_streamed_response(served: Served) -> None:
    add_stream_route(served, "/test/finite", STREAM_CHUNKS)
    sock = connect(served, SMALL_RECEIVE_BUFFER)
    client_port = sock.getsockname()[1]
    connection = eventually(lambda: server_connection(served, client_port), "connected")
    # A small kernel buffer on the server's side: the transport's buffer then fills and
    # drains again and again, and the app writes each time it has drained.
    server_socket = connection.transport.get_extra_info("socket")  # type: ignore[attr-defined]  # uvicorn's protocol state
    server_socket.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 1 << 16)
    send_request(sock, "GET", "/test/finite")
    status, body = read_response(sock, STEADY_PAUSE_S, STEADY_CHUNK)
    sock.close()

    assert status == 200
    assert body == STREAM_CHUNK * STREAM_CHUNKS
    assert paused_s(body) > 4 * SEND_TIMEOUT_S


def test_a_websocket_upgrade_behind_an_unread_response_is_left_to_the_websocket_rules(
    served: Served, trained_models: dict[str, Model]
) -> None:
    sock = connect(served, SMALL_RECEIVE_BUFFER)
    client_port = sock.getsockname()[1]
    key = base64.b64encode(os.urandom(16)).decode()
    send_request(sock, "POST", "/v1/synthesize", synthesize_body(LONG_SPANS, UPGRADE_FPS))
    connection = eventually(lambda: server_connection(served, client_port), "connected")
    transport = connection.transport  # type: ignore[attr-defined]  # uvicorn's protocol state
    eventually(lambda: unsent_bytes(transport) > 0, "the response is written whole")
    sock.sendall(
        f"GET /v1/stream HTTP/1.1\r\nHost: lipstream\r\nUpgrade: websocket\r\n"
        f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
        f"Sec-WebSocket-Version: 13\r\nSec-WebSocket-Protocol: {SUBPROTOCOL_MSGPACK}"
        "\r\n\r\n".encode()
    )
    # The response ended with its bytes unsent, and the upgrade follows: a watch of the
    # HTTP connection would reset it one send timeout later. The WebSocket's rules judge
    # only its app's sends and what is left once its app is done, and the app has sent
    # nothing but the handshake.
    time.sleep(2 * SEND_TIMEOUT_S + 0.2)
    reader = PacedReader(sock, 0.0, 1 << 16)
    status, body = reader.response()
    handshake = reader.until(b"\r\n\r\n")  # read on with the response's reader
    still_open = server_connection(served, client_port) is not None
    sock.close()

    assert status == 200
    expected = trained_models["viseme-lerp"].synthesize(LONG_SPANS, fps=UPGRADE_FPS).frames
    frames = response_frames(body)
    assert len(frames) == len(expected) + return_frames(UPGRADE_FPS)
    np.testing.assert_array_equal(frames[: len(expected)], expected)
    assert handshake.startswith(b"HTTP/1.1 101 ")
    assert still_open
