"""The idle timeout waits ``idle_timeout_s`` after the last message, then closes with 1000.

A ``websocket.Connection`` runs on virtual loop time (``run_on_virtual_time``) against a
scripted client that sends its messages at set loop times and records when the server
closed: probes just before and just after the expected moment see the connection open,
then closed, however slow the machine.
"""

from __future__ import annotations

import asyncio
from collections.abc import Iterator, Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import pytest
from starlette.websockets import WebSocket

from lipstream.config import ServerSettings
from lipstream.models import ModelRegistry
from lipstream.server.catalog import Catalog
from lipstream.server.client_limits import ClientLimits
from lipstream.server.lanes import FairLane
from lipstream.server.lifecycle import Lifecycle
from lipstream.server.metrics import Metrics
from lipstream.server.overload import overload_for
from lipstream.server.state import ServerState
from lipstream.server.websocket import Connection
from lipstream_client import (
    Cancel,
    Done,
    End,
    ErrorMessage,
    Message,
    ProtocolError,
    Ready,
    ServerMessage,
    Start,
    decode,
    encode,
)
from tests.helpers import VirtualClock, run_on_virtual_time
from tests.lipstream.server.harness import fixed_calibration

IDLE_S = 5.0
JUST = 1e-3  # a probe's distance from the moment it checks, in virtual seconds


@dataclass
class Closed:
    at: float
    code: int
    reason: str


class ScriptedClient:
    """The ASGI WebSocket a ``Connection`` serves: ``script`` messages arrive at their loop
    times; what the server sends and when it closes are recorded."""

    def __init__(self, loop: asyncio.AbstractEventLoop, script: list[tuple[float, Message]]):
        self.loop = loop
        self.inbox: asyncio.Queue[Mapping[str, Any]] = asyncio.Queue()
        for at, message in script:
            event = {"type": "websocket.receive", "text": encode(message, "json")}
            loop.call_at(at, self.inbox.put_nowait, event)
        self.received: list[tuple[float, ServerMessage]] = []
        self.closed: Closed | None = None

    async def receive(self) -> Mapping[str, Any]:
        return await self.inbox.get()

    async def send_text(self, text: str) -> None:
        message = decode(text, "json", sender="server")
        assert not isinstance(message, ProtocolError), message
        self.received.append((self.loop.time(), cast(ServerMessage, message)))

    async def send_bytes(self, payload: bytes) -> None:
        raise AssertionError("a JSON connection sends text")

    async def close(self, code: int = 1000, reason: str | None = None) -> None:
        self.closed = Closed(self.loop.time(), code, reason or "")


@pytest.fixture(scope="module")
def lerp_catalog(lerp_dir: Path) -> Catalog:
    with fixed_calibration():
        return Catalog.build(ModelRegistry.load(lerp_dir), ServerSettings())


@pytest.fixture
def state(lerp_catalog: Catalog) -> Iterator[ServerState]:
    settings = ServerSettings(idle_timeout_s=IDLE_S, request_timeout_s=1000.0)
    metrics = Metrics()
    executor = ThreadPoolExecutor(1)
    heavy, speech = FairLane(1, "test-heavy"), FairLane(1, "test-speech")
    yield ServerState(
        lerp_catalog.registry,
        lerp_catalog,
        settings,
        metrics,
        Lifecycle(settings.max_sessions),
        executor,
        heavy,
        speech,
        overload_for(settings, lerp_catalog),
        ClientLimits.from_settings(settings),
    )
    executor.shutdown()
    heavy.shutdown()
    speech.shutdown()


def serve_script(
    state: ServerState, script: list[tuple[float, Message]], probes: list[float]
) -> tuple[ScriptedClient, dict[float, bool]]:
    """Serve ``script`` until the connection closes; whether it was open at each probe."""

    async def scenario(_: VirtualClock) -> tuple[ScriptedClient, dict[float, bool]]:
        loop = asyncio.get_running_loop()
        socket = ScriptedClient(loop, script)
        open_at: dict[float, bool] = {}

        def probe(at: float) -> None:
            open_at[at] = socket.closed is None

        for at in probes:
            loop.call_at(at, probe, at)
        connection = Connection(cast(WebSocket, socket), "json", state)
        await connection.run()
        await asyncio.sleep(max(0.0, max(probes) - loop.time()) + JUST)  # the probes after
        return socket, open_at

    return run_on_virtual_time(scenario)


def idle_close(client: ScriptedClient) -> Closed:
    """The close, after the connection-level ``idle_timeout`` error sent just before it."""
    closed = client.closed
    assert closed is not None, "the server never closed"
    at, last = client.received[-1]
    assert isinstance(last, ErrorMessage)
    assert (last.code, last.id, last.fatal, at) == ("idle_timeout", None, True, closed.at)
    return closed


@pytest.mark.parametrize("arrivals", [(), (3.0,), (3.0, 6.5)])
def test_a_silent_connection_closes_idle_timeout_after_its_last_message(
    state: ServerState, arrivals: tuple[float, ...]
) -> None:
    last = arrivals[-1] if arrivals else 0.0
    script: list[tuple[float, Message]] = [(at, End("nobody")) for at in arrivals]
    due = last + IDLE_S
    client, open_at = serve_script(state, script, [due - JUST, due + JUST])
    closed = idle_close(client)
    assert (closed.at, closed.code, closed.reason) == (due, 1000, "idle_timeout")
    assert open_at == {due - JUST: True, due + JUST: False}
    answered = [(at, m.code) for at, m in client.received[:-1] if isinstance(m, ErrorMessage)]
    assert answered == [(at, "unknown_request") for at in arrivals]


def test_an_active_request_keeps_the_connection_past_the_idle_timeout(
    state: ServerState,
) -> None:
    cancel_at = 4 * IDLE_S
    script: list[tuple[float, Message]] = [
        (1.0, Start("a", "viseme-lerp", "demo")),
        (cancel_at, Cancel("a")),
    ]
    due = cancel_at + IDLE_S
    client, open_at = serve_script(state, script, [1.0 + IDLE_S + JUST, due - JUST, due + JUST])
    closed = idle_close(client)
    assert (closed.at, closed.code, closed.reason) == (due, 1000, "idle_timeout")
    assert open_at == {1.0 + IDLE_S + JUST: True, due - JUST: True, due + JUST: False}
    kinds = [(at, type(m)) for at, m in client.received[:-1]]
    assert kinds == [(1.0, Ready), (cancel_at, Done)]
