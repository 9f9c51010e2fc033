"""Long ``POST /v1/synthesize`` answers in JSON, against a real server: streamed in bounded
pieces while ``/healthz`` and other sessions are served, the bytes of one ``json.dumps`` of
the whole answer, and the frames of answers still being sent counted toward the memory
ceiling."""

from __future__ import annotations

import json
import re
import socket
from collections.abc import Iterator
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import httpx
import msgpack
import numpy as np
import pytest

from lipstream.config import ServerSettings
from lipstream.server.load import MIB, LoadMonitor
from lipstream.server.overload import LoadLimits, Overload, OverloadPolicy
from lipstream.server.rest import JSON_CHUNK_VALUES
from lipstream.server.state import ServerState
from lipstream_client import Done, End, PhonemeItem, Phonemes, Start
from tests.helpers import eventually, return_frames
from tests.lipstream.server.harness import Served, client, serving

PHONEMES = 999  # 99.9 s of 0.1 s phonemes
FPS = 1000  # about 25 MB of JSON: far more than the kernel's buffers hold
FRAMES = 99_901 + return_frames(FPS)  # both ends included, then the return to rest
CHANNELS = 28  # the demo viseme-lerp model's
ITEMS = [
    {"phoneme": "AA1" if index % 2 else "M", "start": index / 10, "end": (index + 1) / 10}
    for index in range(PHONEMES)
]
BODY = {"engine": "viseme-lerp", "character": "demo", "fps": FPS, "items": ITEMS}
ANSWER_BYTES = FRAMES * CHANNELS * 4  # float32 frames
CEILING_MB = 1000
SMALL_RECEIVE_BUFFER = 1 << 16


@pytest.fixture(scope="module")
def served(lerp_dir: Path) -> Iterator[Served]:
    with serving(lerp_dir) as running:
        yield running


def metric(base: str, name: str) -> float:
    text = httpx.get(f"{base}/metrics").text
    found = re.search(rf"^{name} (\S+)$", text, re.M)
    assert found is not None, name
    return float(found.group(1))


def wait_for_metric(base: str, name: str, value: float) -> None:
    eventually(lambda: metric(base, name) == value, f"{name} reads {value:g}")


def post_json(served: Served, accept: str = "application/json") -> socket.socket:
    """A connection with a small receive buffer that has sent the long JSON request."""
    port = int(served.http.rsplit(":", 1)[1])
    sock = socket.socket()
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, SMALL_RECEIVE_BUFFER)
    sock.settimeout(120)  # a bound on a busy machine, not a speed claim
    sock.connect(("127.0.0.1", port))
    body = json.dumps(BODY).encode()
    sock.sendall(
        b"POST /v1/synthesize HTTP/1.1\r\nHost: test\r\nContent-Type: application/json\r\n"
        + f"Accept: {accept}\r\n".encode()
        + f"Content-Length: {len(body)}\r\n\r\n".encode()
        + body
    )
    return sock


class ChunkedReader:
    """Reads an HTTP/1.1 response head, then its chunked body one chunk at a time."""

    def __init__(self, sock: socket.socket) -> None:
        self.sock = sock
        self.buffer = b""

    def _fill(self) -> None:
        data = self.sock.recv(65536)
        assert data, "the server closed the connection mid-answer"
        self.buffer += data

    def _until(self, marker: bytes) -> bytes:
        while marker not in self.buffer:
            self._fill()
        found, self.buffer = self.buffer.split(marker, 1)
        return found

    def _exactly(self, size: int) -> bytes:
        while len(self.buffer) < size:
            self._fill()
        found, self.buffer = self.buffer[:size], self.buffer[size:]
        return found

    def head(self) -> tuple[str, dict[str, str]]:
        status, *lines = self._until(b"\r\n\r\n").decode().split("\r\n")
        headers = dict(line.lower().split(": ", 1) for line in lines)
        return status, headers

    def chunk(self) -> bytes:
        """The next chunk's data (b"" for the last)."""
        size = int(self._until(b"\r\n"), 16)
        data = self._exactly(size)
        assert self._exactly(2) == b"\r\n"
        return data


def expected_json(served: Served) -> bytes:
    """The answer as one ``json.dumps`` of it would write it, built from the msgpack answer
    to the same request (float32 frames; every other field as it is)."""
    answer = httpx.post(
        f"{served.http}/v1/synthesize",
        content=msgpack.packb(BODY),
        headers={"Content-Type": "application/msgpack"},
        timeout=120,
    )
    assert answer.status_code == 200
    fields: dict[str, Any] = msgpack.unpackb(answer.content)
    frames = np.frombuffer(fields["data"], "<f4").reshape(fields["n_frames"], -1)
    fields["data"] = [[float(str(value)) for value in row] for row in frames]
    return json.dumps(fields, allow_nan=False, separators=(",", ":")).encode()


def a_session_is_served(served: Served) -> None:
    with client(served.ws) as ws:
        ws.send(
            Start("s", "viseme-lerp", "demo", fps=60),
            Phonemes("s", (PhonemeItem("HH", 0.0, 0.1), PhonemeItem("AY1", 0.1, 0.3))),
            End("s"),
        )
        assert isinstance(ws.until_done("s")[-1], Done)


def test_a_long_json_answer_is_streamed_while_others_are_served(served: Served) -> None:
    expected = expected_json(served)
    with post_json(served) as sock:
        reader = ChunkedReader(sock)
        status, headers = reader.head()
        assert status == "HTTP/1.1 200 OK"
        assert headers["transfer-encoding"] == "chunked" and "content-length" not in headers
        assert headers["content-type"] == "application/json"
        pieces = [reader.chunk(), reader.chunk()]
        # The client reads no more: the answer is under way, its frames held, and still
        # /healthz and another session are answered.
        assert metric(served.http, "lipstream_rest_answer_bytes") == ANSWER_BYTES
        assert httpx.get(f"{served.http}/healthz").json() == {"status": "ok"}
        a_session_is_served(served)
        assert metric(served.http, "lipstream_rest_answer_bytes") == ANSWER_BYTES
        while piece := reader.chunk():
            pieces.append(piece)
    body = b"".join(pieces)
    assert body == expected
    assert json.loads(body) == json.loads(expected)
    assert len(json.loads(body)["data"]) == FRAMES
    for piece in pieces[1:-1]:  # each piece of rows holds at most JSON_CHUNK_VALUES numbers
        rows = json.loads(b"[" + piece.removeprefix(b",") + b"]")
        assert 0 < sum(map(len, rows)) <= JSON_CHUNK_VALUES
    assert pieces[-1] == b"]}"
    wait_for_metric(served.http, "lipstream_rest_answer_bytes", 0.0)


def test_answers_left_unread_are_held_and_released(served: Served) -> None:
    """JSON answers hold their float32 frames; a msgpack or CSV answer its encoding."""
    packed = httpx.post(
        f"{served.http}/v1/synthesize",
        json=BODY,
        timeout=120,
        headers={"Accept": "application/msgpack"},
    )
    csv = httpx.post(
        f"{served.http}/v1/synthesize", json=BODY, timeout=120, headers={"Accept": "text/csv"}
    )
    assert packed.status_code == csv.status_code == 200
    unread_json = 4
    held = unread_json * ANSWER_BYTES + len(packed.content) + len(csv.content)
    with ExitStack() as stack:
        for _ in range(unread_json):
            stack.enter_context(post_json(served))
        stack.enter_context(post_json(served, "application/msgpack"))
        stack.enter_context(post_json(served, "text/csv"))
        wait_for_metric(served.http, "lipstream_rest_answer_bytes", held)
        assert httpx.get(f"{served.http}/healthz").json() == {"status": "ok"}
        a_session_is_served(served)
    wait_for_metric(served.http, "lipstream_rest_answer_bytes", 0.0)


async def _resident_figure_frozen_at(state: ServerState, rss_mb: float) -> None:
    """Stop the load monitor and fix its resident-memory figure (the injected reading)."""
    state.overload.monitor.stop()
    state.overload.monitor.rss_mb = rss_mb


def test_answers_left_unread_are_refused_beyond_the_memory_ceiling(lerp_dir: Path) -> None:
    with serving(lerp_dir, ServerSettings(max_memory_mb=CEILING_MB)) as served:
        state: ServerState = served.state
        # Room for one and a half answers: the second is admitted with one held, the third
        # would hold two.
        rss_mb = CEILING_MB - 1.5 * ANSWER_BYTES / MIB
        served.call_soon(_resident_figure_frozen_at(state, rss_mb)).result(timeout=10)
        with ExitStack() as stack:
            for held in (1, 2):
                stack.enter_context(post_json(served))
                wait_for_metric(served.http, "lipstream_rest_answer_bytes", held * ANSWER_BYTES)
            refused = httpx.post(f"{served.http}/v1/synthesize", json=BODY, timeout=120)
            assert refused.status_code == 503 and "retry-after" in refused.headers
            error = refused.json()["error"]
            assert (error["code"], error["details"]["reason"]) == ("server_busy", "memory")
            assert httpx.get(f"{served.http}/healthz").json() == {"status": "ok"}
        wait_for_metric(served.http, "lipstream_rest_answer_bytes", 0.0)
        admitted = httpx.post(f"{served.http}/v1/synthesize", json=BODY, timeout=120)
        assert admitted.status_code == 200 and len(admitted.json()["data"]) == FRAMES


def test_bytes_held_for_answers_count_toward_the_memory_ceiling() -> None:
    limits = LoadLimits(max_memory_mb=1000.0, max_lag_ms=50.0, max_busy=0.75, session_cost=0.1)
    monitor = LoadMonitor()
    monitor.rss_mb = 900.0
    overload = Overload(OverloadPolicy(limits), monitor)
    assert overload.request_refusal() is None
    assert overload.request_refusal(held_mb=100.0) is None  # 1000 MiB: at the ceiling
    refusal = overload.request_refusal(held_mb=100.5)
    assert refusal is not None and refusal.reason == "memory"
