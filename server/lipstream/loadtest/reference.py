"""A reference server for capacity ratios: the protocol's traffic with no synthesis.

Sketch: an absolute session count says as much about the machine as about the
code (one 2-core machine held 500 sessions where another held 200). So the
capacity search also measures this server, in the same run, and reports each
engine's count as a ratio of its count. It is a bare ASGI WebSocket app under
uvicorn (the same ``/v1/stream`` path, subprotocols, encodings and uvicorn
WebSocket settings as ``lipstream serve``) that answers a request as the
measured engine would, with the synthesis left out: ``ready`` names the
engine's channels, lookahead and rung; every ``phonemes`` message releases the
frames whose time plus the engine's lookahead the input now covers (time at
most the input's end less the lookahead, as the causal rungs release them), as
``frames`` blocks of the same width and at most the same values per message,
filled with zeros; ``end`` releases the rest (frames up to the input's end)
and the return to rest after them (``return_ms``, the server's default), and
``done`` follows. So a client sees messages of the same size at the same
rate, and what the reference cannot hold is the cost of the protocol, the
sockets and the event loop on this machine.

``ReferenceTraffic`` (what to imitate) reaches uvicorn's workers as JSON in one
private variable (``REFERENCE_ENV``), set only in the reference's own process;
``reference_server`` runs it as a child process on a free loopback port for as
long as a block runs.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from collections.abc import Awaitable, Callable, Iterator, MutableMapping
from dataclasses import asdict, dataclass
from typing import Any, TypeVar

import numpy as np

from lipstream_client import Done, DoneStats, Frames, Phonemes, Ready, Start
from lipstream_client.client import AsyncClient
from lipstream_client.codec import decode, encode, encoding_for_subprotocol, select_subprotocol
from lipstream_client.exceptions import LipstreamClientError, retry_delay_s
from lipstream_client.messages import Encoding, End

from ..config import ServerSettings
from ..engines.base import frame_count
from ..server.request import VALUES_PER_MESSAGE, settle_frames

REFERENCE_ENV = "LIPSTREAM_REFERENCE_TRAFFIC"
APP_FACTORY = "lipstream.loadtest.reference:app_from_environment"
STREAM_PATH = "/v1/stream"
READY_TIMEOUT_S = 60.0
READY_ATTEMPTS = 30
"""Tries at learning an engine's traffic: right after a probe past its capacity the server
may still be busy draining it, and refuse the connection (``server_busy``) for a while."""
MAX_MESSAGE_BYTES = 1 << 20

Scope = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[MutableMapping[str, Any]]]
Send = Callable[[MutableMapping[str, Any]], Awaitable[None]]
T = TypeVar("T")


@dataclass(frozen=True)
class ReferenceTraffic:
    """What the reference imitates: the engine's output channels, its declared lookahead
    and rung, the server's limit of values per ``frames`` message and its return to rest
    after ``end`` (ms)."""

    channels: tuple[str, ...]
    lookahead_ms: float = 0.0
    fidelity: str = "reference"
    values_per_message: int = VALUES_PER_MESSAGE
    return_ms: float = ServerSettings().return_ms

    def to_json(self) -> str:
        return json.dumps(asdict(self))

    @classmethod
    def from_json(cls, text: str) -> ReferenceTraffic:
        fields = json.loads(text)
        return cls(
            channels=tuple(str(name) for name in fields["channels"]),
            lookahead_ms=float(fields["lookahead_ms"]),
            fidelity=str(fields["fidelity"]),
            values_per_message=int(fields["values_per_message"]),
            return_ms=float(fields["return_ms"]),
        )


class _Request:
    """One request's frame clock: frames released so far and the input's end."""

    def __init__(self, start: Start, traffic: ReferenceTraffic) -> None:
        self.start = start
        self.width = len(traffic.channels)
        self.rows_per_message = max(1, traffic.values_per_message // self.width)
        self.lookahead_s = traffic.lookahead_ms / 1000.0
        self.return_frames = max(1, settle_frames(traffic.return_ms, start.fps))
        self.covered = 0.0
        self.sent = 0
        self.seq = 0

    def release(self, until: int) -> list[Frames]:
        """Frames blocks for frames ``sent`` .. ``until`` - 1, zeros of the engine's width."""
        blocks: list[Frames] = []
        for first in range(self.sent, until, self.rows_per_message):
            rows = min(self.rows_per_message, until - first)
            data = np.zeros((rows, self.width), dtype="<f4").tobytes()
            start = self.start
            blocks.append(Frames(start.id, self.seq, first, start.fps, self.width, data))
            self.seq += 1
        self.sent = max(self.sent, until)
        return blocks

    def feed(self, message: Phonemes) -> list[Frames]:
        self.covered = max([self.covered, *(item.end for item in message.items)])
        reach = self.covered - self.lookahead_s
        return self.release(frame_count(reach, self.start.fps) if reach >= 0 else 0)

    def finish(self) -> list[Frames | Done]:
        frames = frame_count(self.covered, self.start.fps) if self.covered > 0 else 0
        if frames:
            frames += self.return_frames
        return [*self.release(frames), Done(self.start.id, DoneStats(frames=frames))]


class ReferenceApp:
    """The ASGI app: ``/v1/stream`` as above; any HTTP path answers 200 (a health check)."""

    def __init__(self, traffic: ReferenceTraffic) -> None:
        self.traffic = traffic

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "http":
            await _answer_ok(send)
        elif scope["type"] == "websocket" and scope["path"] == STREAM_PATH:
            await self._session(scope, receive, send)
        elif scope["type"] == "websocket":
            await send({"type": "websocket.close", "code": 1008})

    async def _session(self, scope: Scope, receive: Receive, send: Send) -> None:
        await receive()  # websocket.connect
        chosen = select_subprotocol(scope.get("subprotocols", []))
        encoding = encoding_for_subprotocol(chosen) or "msgpack"
        await send({"type": "websocket.accept", "subprotocol": chosen})
        requests: dict[str, _Request] = {}
        while True:
            event = await receive()
            if event["type"] != "websocket.receive":
                return
            payload = event.get("bytes") if encoding == "msgpack" else event.get("text")
            message = decode(payload or b"", encoding, max_size=MAX_MESSAGE_BYTES)
            for reply in self._answer(message, requests):
                await _send(send, reply, encoding)

    def _answer(self, message: object, requests: dict[str, _Request]) -> list[Any]:
        if isinstance(message, Start):
            requests[message.id] = _Request(message, self.traffic)
            return [self._ready(message)]
        if isinstance(message, Phonemes) and message.id in requests:
            return list(requests[message.id].feed(message))
        if isinstance(message, End) and message.id in requests:
            return requests.pop(message.id).finish()
        return []  # a cancel, an unknown id or a message it cannot read: nothing to imitate

    def _ready(self, start: Start) -> Ready:
        return Ready(
            start.id,
            start.engine,
            start.character,
            start.fps,
            self.traffic.channels,
            self.traffic.lookahead_ms,
            self.traffic.fidelity,
            latency_budget_ms=start.latency_budget_ms,
        )


async def _send(send: Send, message: Any, encoding: Encoding) -> None:
    payload = encode(message, encoding, validate=False)
    if isinstance(payload, bytes):
        await send({"type": "websocket.send", "bytes": payload})
    else:
        await send({"type": "websocket.send", "text": payload})


async def _answer_ok(send: Send) -> None:
    body = b'{"status":"ok"}'
    headers = [(b"content-type", b"application/json"), (b"content-length", b"%d" % len(body))]
    await send({"type": "http.response.start", "status": 200, "headers": headers})
    await send({"type": "http.response.body", "body": body})


async def _ready_once(url: str, start: Start, token: str | None, encoding: Encoding) -> Ready:
    async with AsyncClient(url, encoding, token) as client:
        stream = await client.start_request(start)
        ready = await asyncio.wait_for(stream.ready(), READY_TIMEOUT_S)
        await stream.cancel()
        await asyncio.wait_for(stream.done(), READY_TIMEOUT_S)
        return ready


async def with_retries(
    attempt: Callable[[], Awaitable[T]],
    attempts: int = READY_ATTEMPTS,
    sleep: Callable[[float], Awaitable[None]] = asyncio.sleep,
) -> T:
    """``attempt()``, tried again while it fails with a retryable error (a busy server), up
    to ``attempts`` tries, each after the wait the server asked for (``retry_delay_s``)."""
    for tried in range(attempts):
        try:
            return await attempt()
        except LipstreamClientError as error:
            if not error.retryable or tried + 1 == attempts:
                raise
            await sleep(retry_delay_s(error, tried))
    raise ValueError(f"attempts must be at least 1, got {attempts}")


async def _ready_of(url: str, start: Start, token: str | None, encoding: Encoding) -> Ready:
    return await with_retries(lambda: _ready_once(url, start, token, encoding))


def engine_traffic(
    url: str,
    engine: str,
    character: str,
    fps: float,
    latency_budget_ms: float | None = None,
    token: str | None = None,
    encoding: Encoding = "msgpack",
) -> ReferenceTraffic:
    """What the engine at ``url`` sends for such a request: one request's ``ready``
    (channels, lookahead, rung), cancelled before any input."""
    start = Start("reference-traffic", engine, character, fps, latency_budget_ms=latency_budget_ms)
    ready = asyncio.run(_ready_of(url, start, token, encoding))
    return ReferenceTraffic(ready.channels, ready.lookahead_ms, ready.fidelity)


def app_from_environment() -> ReferenceApp:
    """The worker entry: the app for the traffic described in ``REFERENCE_ENV``."""
    return ReferenceApp(ReferenceTraffic.from_json(os.environ[REFERENCE_ENV]))


def run(port: int, workers: int) -> None:
    """Serve ``app_from_environment`` on loopback ``port`` with ``workers`` processes, with
    the WebSocket settings ``lipstream serve`` uses."""
    import uvicorn

    uvicorn.run(
        APP_FACTORY,
        factory=True,
        host="127.0.0.1",
        port=port,
        workers=workers if workers > 1 else None,
        log_level="warning",
        ws_max_size=2 * MAX_MESSAGE_BYTES,
        ws_per_message_deflate=False,
        lifespan="off",
    )


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port: int = probe.getsockname()[1]
        return port


def _answers(port: int) -> bool:
    opener = urllib.request.build_opener(urllib.request.ProxyHandler({}))
    try:
        with opener.open(f"http://127.0.0.1:{port}/healthz", timeout=1.0) as answer:
            return bool(answer.status == 200)
    except (OSError, urllib.error.HTTPError):
        return False


@contextlib.contextmanager
def reference_server(traffic: ReferenceTraffic, workers: int = 1) -> Iterator[str]:
    """Run the reference server in a child process on a free loopback port; yields its
    ``ws://`` URL of ``/v1/stream``, and stops it when the block ends."""
    port = _free_port()
    environment = {**os.environ, REFERENCE_ENV: traffic.to_json()}
    command = [sys.executable, "-m", "lipstream.loadtest.reference", str(port), str(workers)]
    process = subprocess.Popen(command, env=environment, stdout=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + READY_TIMEOUT_S
        while not _answers(port):
            if process.poll() is not None:
                raise RuntimeError(f"the reference server exited with code {process.returncode}")
            if time.monotonic() > deadline:
                raise RuntimeError(f"the reference server did not answer in {READY_TIMEOUT_S} s")
            time.sleep(0.1)
        yield f"ws://127.0.0.1:{port}{STREAM_PATH}"
    finally:
        process.terminate()
        try:
            process.wait(timeout=10.0)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


if __name__ == "__main__":
    run(int(sys.argv[1]), int(sys.argv[2]))
