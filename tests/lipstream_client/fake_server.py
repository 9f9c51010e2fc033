"""A tiny protocol-v1 server for client tests: deterministic frames, scripted failures.

It runs ``websockets.asyncio.server.serve`` on 127.0.0.1 in its own thread
and speaks docs/reference/protocol.md with the real codec. Frame ``i`` of a request
whose ``start.options`` holds ``{"offset": o}`` is ``[i / 1024 + o, 1 - i /
1024]`` (exact in float32), so a test knows every value independently.
Frames ``i`` with ``i / fps < end`` of the latest phoneme go out after each
``phonemes`` message, the rest (``i / fps <= end``) after ``end``.

Scripted behaviour: engine ``missing`` gets a fatal ``unknown_engine``;
character ``close-1001`` / ``close-1011`` makes the server close the
connection with that code (1011 after a connection-level ``internal_error``);
``busy=True`` refuses every connection with ``server_busy`` and 1013;
``busy_starts=n`` answers the first n ``start`` messages with a request-scope
``server_busy`` (``retry_after_ms`` 50), the connection kept;
``token`` requires ``Authorization: Bearer <token>``; ``refuse_upgrade``
answers the upgrade with HTTP 403.
"""

from __future__ import annotations

import asyncio
import math
import threading
from dataclasses import dataclass, field
from http import HTTPStatus
from typing import Any, Self

from websockets.asyncio.server import Server, ServerConnection, serve
from websockets.http11 import Request, Response
from websockets.typing import Subprotocol

from lipstream_client import (
    SUBPROTOCOLS,
    Cancel,
    Done,
    DoneStats,
    End,
    ErrorMessage,
    Frames,
    Interrupt,
    Message,
    Phonemes,
    ProtocolError,
    Ready,
    Start,
    decode,
    encode,
    encoding_for_subprotocol,
)
from lipstream_client.messages import JsonValue

CHANNELS = ("jawOpen", "mouthClose")
DEFAULT_RETURN_MS = 100.0
SCALE = 1024.0


def expected_row(index: int, offset: float = 0.0) -> list[float]:
    """The fake server's frame ``index`` of a request with ``offset``."""
    return [index / SCALE + offset, 1.0 - index / SCALE]


@dataclass
class _Request:
    start: Start
    offset: float
    sent: int = 0
    seq: int = 0
    covered: float = 0.0
    rows: dict[int, list[float]] = field(default_factory=dict)


class FakeServer:
    """Start with ``with FakeServer(...) as server:``; connect to ``server.url``."""

    def __init__(
        self,
        *,
        busy: bool = False,
        busy_starts: int = 0,
        token: str | None = None,
        refuse_upgrade: bool = False,
    ) -> None:
        self.busy = busy
        self.busy_starts = busy_starts
        self.token = token
        self.refuse_upgrade = refuse_upgrade
        self.received: list[Message | ProtocolError] = []
        self.headers: list[dict[str, str]] = []
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._loop.run_forever, daemon=True)
        self._server: Server | None = None
        self.port = 0

    @property
    def url(self) -> str:
        return f"ws://127.0.0.1:{self.port}/v1/stream"

    def __enter__(self) -> Self:
        self._thread.start()
        future = asyncio.run_coroutine_threadsafe(self._start(), self._loop)
        future.result(10)
        return self

    def __exit__(self, *exc: object) -> None:
        asyncio.run_coroutine_threadsafe(self._stop(), self._loop).result(10)
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(10)
        self._loop.close()

    async def _start(self) -> None:
        self._server = await serve(
            self._handle,
            "127.0.0.1",
            0,
            subprotocols=[Subprotocol(name) for name in SUBPROTOCOLS],
            process_request=self._process_request,
            compression=None,
        )
        self.port = self._server.sockets[0].getsockname()[1]

    async def _stop(self) -> None:
        assert self._server is not None
        self._server.close()
        await self._server.wait_closed()

    def _process_request(self, connection: ServerConnection, request: Request) -> Response | None:
        self.headers.append({key.lower(): value for key, value in request.headers.raw_items()})
        if self.refuse_upgrade:
            return connection.respond(HTTPStatus.FORBIDDEN, "no subprotocol in common\n")
        return None

    async def _handle(self, connection: ServerConnection) -> None:
        encoding = encoding_for_subprotocol(connection.subprotocol) or "msgpack"
        session = _Session(self, connection, encoding)
        await session.run()


class _Session:
    def __init__(self, server: FakeServer, connection: ServerConnection, encoding: Any) -> None:
        self.server = server
        self.connection = connection
        self.encoding = encoding
        self.requests: dict[str, _Request] = {}

    async def send(self, message: Message) -> None:
        await self.connection.send(encode(message, self.encoding))

    async def refuse(self, code: str, close_code: int) -> None:
        await self.send(ErrorMessage(code, f"refused: {code}", None, True))
        await self.connection.close(close_code, code)

    async def run(self) -> None:
        if self.server.busy:
            await self.refuse("server_busy", 1013)
            return
        authorization = (
            self.connection.request.headers.get("Authorization")
            if self.connection.request
            else None
        )
        if self.server.token is not None and authorization != f"Bearer {self.server.token}":
            await self.refuse("unauthorized", 1008)
            return
        async for data in self.connection:
            message = decode(data, self.encoding, sender="client")
            self.server.received.append(message)
            if isinstance(message, ProtocolError):
                await self.send(message.to_message())
                continue
            await self.handle(message)

    async def handle(self, message: Message) -> None:
        if isinstance(message, Start):
            await self.on_start(message)
            return
        request = self.requests.get(message.id or "")
        if request is None:
            await self.send(ErrorMessage("unknown_request", "no such request", message.id, False))
        elif isinstance(message, Phonemes):
            request.covered = message.items[-1].end
            await self.emit(request, math.ceil(request.covered * request.start.fps) - 1)
        elif isinstance(message, End):
            await self.emit(request, math.floor(request.covered * request.start.fps + 1e-9))
            await self.finish(request, "end", request.sent)
        elif isinstance(message, Cancel):
            await self.finish(request, "cancel", request.sent)
        elif isinstance(message, Interrupt):
            await self.on_interrupt(request, message)

    async def on_start(self, start: Start) -> None:
        if start.character.startswith("close-"):
            code = int(start.character.removeprefix("close-"))
            if code == 1011:
                await self.refuse("internal_error", 1011)
            else:
                await self.connection.close(code, "shutting_down")
            return
        if start.engine == "missing":
            await self.send(
                ErrorMessage(
                    "unknown_engine", f"engine: no engine {start.engine!r}", start.id, True
                )
            )
            return
        if self.server.busy_starts > 0:
            self.server.busy_starts -= 1
            details: dict[str, JsonValue] = {"reason": "loop_busy", "retry_after_ms": 50}
            await self.send(ErrorMessage("server_busy", "busy", start.id, True, details))
            return
        offset = start.options.get("offset", 0.0)
        assert isinstance(offset, int | float), offset  # the tests' own option
        self.requests[start.id] = _Request(start, float(offset))
        await self.send(
            Ready(start.id, start.engine, start.character, start.fps, CHANNELS, 0.0, "exact")
        )

    async def emit(self, request: _Request, last: int) -> None:
        if last < request.sent:
            return
        rows = [expected_row(index, request.offset) for index in range(request.sent, last + 1)]
        await self.send_rows(request, request.sent, rows)
        request.sent = last + 1

    async def send_rows(self, request: _Request, first: int, rows: list[list[float]]) -> None:
        for offset, row in enumerate(rows):
            request.rows[first + offset] = row
        await self.send(
            Frames.from_rows(request.start.id, request.seq, first, request.start.fps, rows)
        )
        request.seq += 1

    async def on_interrupt(self, request: _Request, interrupt: Interrupt) -> None:
        fps = request.start.fps
        cut = math.ceil(interrupt.at * fps - 1e-9)
        return_ms = interrupt.return_ms if interrupt.return_ms is not None else DEFAULT_RETURN_MS
        steps = max(1, round(return_ms / 1000.0 * fps))
        face = request.rows.get(cut - 1, expected_row(cut - 1, request.offset))
        rows = [[value * (1.0 - (step + 1) / steps) for value in face] for step in range(steps)]
        await self.send_rows(request, cut, rows)
        await self.finish(request, "interrupt", cut + steps)

    async def finish(self, request: _Request, reason: Any, frames: int) -> None:
        del self.requests[request.start.id]
        await self.send(Done(request.start.id, DoneStats(frames, 1.5, 2.5), reason))
