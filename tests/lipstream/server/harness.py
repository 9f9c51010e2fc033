"""A real uvicorn server in a background thread, and a small synchronous protocol client.

The server runs ``create_app`` exactly as ``lipstream serve`` configures it
(``runner.uvicorn_options``) on a free loopback port, with its own event
loop, so tests can also run coroutines on it (``Served.call_soon``). The client is
the real ``websockets`` client speaking through ``lipstream_client.codec``.
"""

from __future__ import annotations

import asyncio
import tempfile
import threading
from collections import deque
from collections.abc import Coroutine, Iterator
from concurrent.futures import Future
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import pytest
import uvicorn
from fastapi import FastAPI
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import ClientConnection, connect

from lipstream.config import ServerSettings
from lipstream.engines.base import Model, Rung
from lipstream.server.app import create_app
from lipstream.server.calibration import ComputeCost
from lipstream.server.runner import uvicorn_options
from lipstream.server.startup import server_of
from lipstream.server.state import ServerState
from lipstream_client import (
    Done,
    Encoding,
    ErrorMessage,
    Frames,
    Message,
    ProtocolError,
    decode,
    encode,
    subprotocol_for,
)
from tests.helpers import eventually, free_port

RECEIVE_TIMEOUT_S = 10.0
T = TypeVar("T")


@dataclass
class Served:
    """A running server: its URLs, app and event loop."""

    http: str
    ws: str
    app: FastAPI
    loop: asyncio.AbstractEventLoop
    server: uvicorn.Server

    def call_soon(self, coroutine: Coroutine[Any, Any, T]) -> Future[T]:
        """Start ``coroutine`` on the server's event loop; its result arrives in the future."""
        return asyncio.run_coroutine_threadsafe(coroutine, self.loop)

    @property
    def state(self) -> ServerState:
        """The app's server state, once it has started up."""
        state = server_of(self.server.lifespan.state)
        assert state is not None, "the server has not started up"
        return state


@contextmanager
def serving(
    models: Path,
    settings: ServerSettings | None = None,
    app: FastAPI | None = None,
    *,
    measured_calibration: bool = False,
) -> Iterator[Served]:
    """Serve ``models`` (or ``app``, built from them) on a free loopback port until the
    block ends. Its catalog is calibrated by ``fixed_calibration`` (a loaded machine's
    measurement could refuse a model as too costly, or choose other rungs) unless
    ``measured_calibration``, for the tests of calibration itself. Settings that name no
    recordings directory get a scratch one, so no test serves characters recorded under the
    user's ``$LIPSTREAM_HOME``."""
    with ExitStack() as stack:
        if not measured_calibration:
            stack.enter_context(fixed_calibration())
        settings = settings or ServerSettings()
        if settings.recordings_dir is None:
            scratch = stack.enter_context(tempfile.TemporaryDirectory(prefix="recordings-"))
            settings = settings.with_changes(recordings_dir=Path(scratch))
        yield stack.enter_context(_serving(models, settings, app))


@contextmanager
def _serving(
    models: Path, settings: ServerSettings | None, app: FastAPI | None
) -> Iterator[Served]:
    settings = (settings or ServerSettings()).with_changes(log_level="warning")
    app = app or create_app(models, settings)
    port = free_port()
    config = uvicorn.Config(app, host="127.0.0.1", port=port, **uvicorn_options(settings))
    server = uvicorn.Server(config)
    loop = asyncio.new_event_loop()
    thread = threading.Thread(target=loop.run_until_complete, args=(server.serve(),), daemon=True)
    thread.start()
    eventually(lambda: server.started or not thread.is_alive(), "the test server starts")
    if not server.started:
        raise RuntimeError("the test server did not start")
    try:
        yield Served(
            f"http://127.0.0.1:{port}", f"ws://127.0.0.1:{port}/v1/stream", app, loop, server
        )
    finally:
        server.should_exit = True
        thread.join(timeout=15)
        loop.close()


# What every rung costs under ``fixed_calibration``: rung choices then follow from the
# models' lookahead alone, not from how fast a (loaded) machine ran the calibration.
FIXED_COMPUTE_MS = 1.0


def _fixed_cost(model: Model, rung: Rung, *checks: object) -> ComputeCost:
    """``calibration.measure``'s stand-in; its guard, share bound and place go unused."""
    return ComputeCost(FIXED_COMPUTE_MS, FIXED_COMPUTE_MS, per_frame_ms=0.001)


@contextmanager
def fixed_calibration() -> Iterator[None]:
    """Catalogs built meanwhile (a server's too) measure every rung at ``FIXED_COMPUTE_MS``;
    the warm-up still runs, since it compiles the engines' kernels."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr("lipstream.server.catalog.measure", _fixed_cost)
        yield


class Client:
    """A synchronous lipstream connection: typed messages in and out."""

    def __init__(self, connection: ClientConnection, encoding: Encoding) -> None:
        self.connection = connection
        self.encoding = encoding
        self.held: deque[Message] = deque()

    def send(self, *messages: Message) -> None:
        for message in messages:
            self.connection.send(encode(message, self.encoding))

    def send_raw(self, payload: bytes | str) -> None:
        self.connection.send(payload)

    def recv(self, timeout: float = RECEIVE_TIMEOUT_S) -> Message:
        """The next message (held ones first); it must decode, since the server never
        sends what the codec rejects."""
        if self.held:
            return self.held.popleft()
        return self._receive(timeout)

    def _receive(self, timeout: float) -> Message:
        payload = self.connection.recv(timeout=timeout)
        assert isinstance(payload, bytes) == (self.encoding == "msgpack"), (
            "msgpack travels in binary frames, JSON in text frames"
        )
        message = decode(payload, self.encoding, sender="server", max_size=1 << 24)
        assert not isinstance(message, ProtocolError), message
        return message

    def until_done(self, identifier: str, limit: int = 10_000) -> list[Message]:
        """Messages of request ``identifier`` up to and including its done or fatal error;
        other requests' messages are held back, in order, for later calls."""
        collected: list[Message] = []
        skipped: deque[Message] = deque()
        for _ in range(limit):
            message = self.recv()
            if getattr(message, "id", None) != identifier:
                skipped.append(message)
                continue
            collected.append(message)
            if isinstance(message, Done) or (isinstance(message, ErrorMessage) and message.fatal):
                skipped.extend(self.held)
                self.held = skipped
                return collected
        raise AssertionError(f"no done for {identifier!r} within {limit} messages")

    def closed(self, timeout: float = RECEIVE_TIMEOUT_S) -> tuple[list[Message], int | None, str]:
        """Read until the server closes: (messages before the close, close code, reason)."""
        messages: list[Message] = []
        try:
            while True:
                messages.append(self.recv(timeout))
        except ConnectionClosed as closed:
            frame = closed.rcvd
            return messages, (frame.code if frame else None), (frame.reason if frame else "")


@contextmanager
def client(url: str, encoding: Encoding = "msgpack", **options: Any) -> Iterator[Client]:
    """Connect offering ``encoding``'s subprotocol (per-message deflate not offered)."""
    options.setdefault("subprotocols", [subprotocol_for(encoding)])
    options.setdefault("compression", None)
    options.setdefault("max_size", None)
    options.setdefault("open_timeout", 10)
    with connect(url, **options) as connection:
        yield Client(connection, encoding)


def frame_rows(messages: list[Message]) -> dict[int, list[float]]:
    """Frame index -> row, later blocks replacing earlier ones (as the protocol says)."""
    rows: dict[int, list[float]] = {}
    for message in messages:
        if isinstance(message, Frames):
            for offset, row in enumerate(message.rows()):
                rows[message.first_frame + offset] = row
    return rows


def only_errors(messages: list[Message]) -> list[ErrorMessage]:
    """``messages``, every one of which must be an ``ErrorMessage``."""
    errors = [message for message in messages if isinstance(message, ErrorMessage)]
    assert len(errors) == len(messages), messages
    return errors
