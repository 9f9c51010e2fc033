"""BoundedAcceptLoop takes at most ACCEPTS_PER_TURN connections per readiness callback and
leaves the rest in the kernel's queue (asyncio's own loop takes them all), takes a filling
queue's excess over half its capacity, and answers its gate's refusals on the bare socket
without building a protocol. Counted on a real listening socket: what is still queued after
the callback is what a plain accept() finds."""

from __future__ import annotations

import asyncio
import json
import socket
import threading
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import httpx
import pytest

from lipstream.config import ServerSettings
from lipstream.server.accept_gate import ServerGate, is_stream_upgrade
from lipstream.server.accept_loop import (
    ACCEPTS_PER_TURN,
    LOOP,
    REFUSALS_PER_TURN,
    AcceptGate,
    BoundedAcceptLoop,
)
from lipstream.server.handshake import CLIENT_PROBE_LANE
from lipstream.server.runner import uvicorn_options
from lipstream_client.errors import TOO_MANY_CLIENT_CONNECTIONS
from tests.lipstream.server.harness import Served, client, serving

PENDING = 40
ANSWER = b"HTTP/1.1 503 Service Unavailable\r\ncontent-length: 0\r\n\r\n"


@contextmanager
def pending_connections(
    count: int, backlog: int = 2048
) -> Iterator[tuple[socket.socket, list[socket.socket]]]:
    """A listening loopback socket with ``count`` connections waiting to be accepted, and
    their client ends."""
    with ExitStack() as stack:
        listener = stack.enter_context(socket.socket())
        listener.bind(("127.0.0.1", 0))
        listener.listen(backlog)
        clients = []
        for _ in range(count):
            client = stack.enter_context(socket.socket())
            client.connect(listener.getsockname())
            clients.append(client)
        listener.setblocking(False)
        yield listener, clients


def still_queued(listener: socket.socket) -> int:
    queued = 0
    while True:
        try:
            connection, _ = listener.accept()
        except BlockingIOError:
            return queued
        connection.close()
        queued += 1


@dataclass
class Built:
    """A protocol factory that counts the protocols built."""

    protocols: list[asyncio.Protocol] = field(default_factory=list)

    def __call__(self) -> asyncio.Protocol:
        protocol = asyncio.Protocol()
        self.protocols.append(protocol)
        return protocol


@dataclass
class EveryOther:
    """A gate refusing every other connection it is asked about."""

    asked: int = 0

    def refusal(self, connection: socket.socket, address: str) -> bytes | None:
        self.asked += 1
        return ANSWER if self.asked % 2 == 0 else None


def one_turn(
    loop: asyncio.AbstractEventLoop, listener: socket.socket, built: Built | None = None
) -> None:
    factory = built if built is not None else asyncio.Protocol
    try:
        loop._accept_connection(factory, listener, None, None, 2048)  # type: ignore[attr-defined]
    finally:
        loop.run_until_complete(asyncio.sleep(0.01))
        loop.close()


def accepted_in_one_turn(loop: asyncio.AbstractEventLoop, pending: int, backlog: int) -> int:
    with pending_connections(pending, backlog) as (listener, _):
        one_turn(loop, listener)
        return pending - still_queued(listener)


def test_one_turn_accepts_at_most_the_bound_and_leaves_the_rest_queued() -> None:
    assert accepted_in_one_turn(BoundedAcceptLoop(), PENDING, 2048) == ACCEPTS_PER_TURN < PENDING
    assert accepted_in_one_turn(asyncio.SelectorEventLoop(), PENDING, 2048) == PENDING


def test_a_queue_over_half_full_is_taken_down_to_half() -> None:
    # 60 queued of 64: the bound and the 28 beyond half the queue.
    assert accepted_in_one_turn(BoundedAcceptLoop(), 60, 64) == ACCEPTS_PER_TURN + 60 - 32
    assert accepted_in_one_turn(BoundedAcceptLoop(), 30, 64) == ACCEPTS_PER_TURN


def test_the_gates_refusals_are_answered_without_a_protocol_and_beside_the_bound() -> None:
    loop = BoundedAcceptLoop()
    gate = EveryOther()
    loop.accept_gate = gate
    built = Built()
    with pending_connections(PENDING) as (listener, clients):
        one_turn(loop, listener, built)
        left = still_queued(listener)
        # Sixteen served, and the fifteen refused between them: the bound counts only the
        # connections that get a protocol.
        assert len(built.protocols) == ACCEPTS_PER_TURN
        assert gate.asked == 2 * ACCEPTS_PER_TURN - 1 == PENDING - left
        for index, client in enumerate(clients[: gate.asked]):
            client.settimeout(5.0)
            if index % 2 == 1:
                assert client.recv(1024) == ANSWER and client.recv(1024) == b""  # then closed


def test_refusals_too_have_a_bound_per_turn() -> None:
    loop = BoundedAcceptLoop()

    class RefuseAll:
        def refusal(self, connection: socket.socket, address: str) -> bytes | None:
            return ANSWER

    loop.accept_gate = RefuseAll()
    built = Built()
    pending = REFUSALS_PER_TURN + 8
    with pending_connections(pending) as (listener, _):
        one_turn(loop, listener, built)
        assert still_queued(listener) == 8 and built.protocols == []


def test_the_server_runs_on_it() -> None:
    assert uvicorn_options(ServerSettings())["loop"] == LOOP


@pytest.fixture(scope="module")
def capped_gate(lerp_dir: Path) -> Iterator[Served]:
    with serving(lerp_dir, ServerSettings(max_client_connections=2)) as served:
        yield served


@dataclass
class Recording:
    """A gate passing every question on to ``gate``, keeping its answers."""

    gate: AcceptGate
    answers: list[tuple[str, bytes | None]] = field(default_factory=list)

    def refusal(self, connection: socket.socket, address: str) -> bytes | None:
        answer = self.gate.refusal(connection, address)
        self.answers.append((address, answer))
        return answer


async def saturate(served: Served, host: str, by: int) -> None:
    """On the server's loop: ``host`` holds ``by`` more connections over the cap than now,
    all of them waiting (or, negative, that many fewer)."""
    limits = served.state.clients
    for _ in range(limits.max_connections + CLIENT_PROBE_LANE):
        if by > 0:
            limits.opened(host, 0.0)
        else:
            limits.closed(host, 0.0)
    for _ in range(CLIENT_PROBE_LANE):
        if by > 0:
            limits.wait(host)
        else:
            limits.done_waiting(host)


def test_a_live_server_refuses_a_saturated_address_at_accept(capped_gate: Served) -> None:
    """The serving loop carries the flood gate: a connection from an address at its cap with
    its probe lane full is answered by the gate (no protocol) with the coded 503, while
    another address is served."""
    loop = capped_gate.loop
    assert isinstance(loop, BoundedAcceptLoop) and isinstance(loop.accept_gate, ServerGate)
    recording = Recording(loop.accept_gate)
    loop.accept_gate = recording
    host = "127.0.0.3"
    capped_gate.call_soon(saturate(capped_gate, host, 1)).result(timeout=10)
    try:
        port = int(capped_gate.http.rsplit(":", 1)[1])
        with socket.create_connection(("127.0.0.1", port), source_address=(host, 0)) as flood:
            flood.settimeout(10.0)
            received = b""
            while chunk := flood.recv(4096):
                received += chunk
        head, _, body = received.partition(b"\r\n\r\n")
        assert head.startswith(b"HTTP/1.1 503 ")
        error = json.loads(body)["error"]
        assert error["code"] == TOO_MANY_CLIENT_CONNECTIONS
        assert error["details"]["reason"] == "connections"
        assert [(address, answer is not None) for address, answer in recording.answers] == [
            (host, True)
        ]
        assert httpx.get(f"{capped_gate.http}/healthz").json() == {"status": "ok"}
        assert recording.answers[-1] == ("127.0.0.1", None)
    finally:
        capped_gate.call_soon(saturate(capped_gate, host, -1)).result(timeout=10)
        loop.accept_gate = recording.gate


UPGRADE_HEAD = (
    b"GET /v1/stream?token=x HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\n"
    b"Connection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
    b"Sec-WebSocket-Version: 13\r\n\r\n"
)


def test_a_stream_upgrade_is_told_from_a_whole_head() -> None:
    assert is_stream_upgrade(UPGRADE_HEAD)
    assert is_stream_upgrade(
        UPGRADE_HEAD.replace(b"?token=x", b"").replace(b"websocket", b"WebSocket")
    )
    assert not is_stream_upgrade(UPGRADE_HEAD[:-2])  # the head is not complete yet
    assert not is_stream_upgrade(UPGRADE_HEAD.replace(b"/v1/stream", b"/healthz"))
    assert not is_stream_upgrade(UPGRADE_HEAD.replace(b"/v1/stream", b"/v1/streams"))
    assert not is_stream_upgrade(UPGRADE_HEAD.replace(b"GET ", b"POST "))
    assert not is_stream_upgrade(UPGRADE_HEAD.replace(b"Upgrade: websocket\r\n", b""))
    assert not is_stream_upgrade(b"GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n")


@pytest.fixture(scope="module")
def always_busy(lerp_dir: Path) -> Iterator[Served]:
    # Any measured busy time at all exceeds this limit: every new session is refused.
    with serving(lerp_dir, ServerSettings(max_loop_busy=1e-9)) as served:
        yield served


def sent_while_the_loop_waits(served: Served, request: bytes) -> bytes:
    """Connect and send ``request`` while the server's loop is held, so that the whole head
    is there when the loop accepts the connection; the server's whole answer."""
    release = threading.Event()

    async def hold() -> None:
        release.wait(timeout=30)

    held = served.call_soon(hold())
    port = int(served.http.rsplit(":", 1)[1])
    try:
        connection = socket.create_connection(("127.0.0.1", port))
        connection.sendall(request)
    finally:
        release.set()
    held.result(timeout=30)
    with connection:
        connection.settimeout(10.0)
        received = b""
        while chunk := connection.recv(4096):
            received += chunk
    return received


def test_a_busy_server_refuses_an_upgrade_at_accept_and_still_answers_a_probe(
    always_busy: Served,
) -> None:
    loop = always_busy.loop
    assert isinstance(loop, BoundedAcceptLoop)
    recording = Recording(loop.accept_gate)  # type: ignore[arg-type]
    loop.accept_gate = recording
    try:
        answer = sent_while_the_loop_waits(always_busy, UPGRADE_HEAD)
        head, _, body = answer.partition(b"\r\n\r\n")
        assert head.startswith(b"HTTP/1.1 503 ") and b"retry-after: " in head.lower()
        error = json.loads(body)["error"]
        assert (error["code"], error["details"]["reason"]) == ("server_busy", "loop_busy")
        assert [(address, answer is not None) for address, answer in recording.answers] == [
            ("127.0.0.1", True)
        ]
        probe = sent_while_the_loop_waits(
            always_busy, b"GET /healthz HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n"
        )
        assert probe.startswith(b"HTTP/1.1 200 ") and recording.answers[-1][1] is None
        metrics = httpx.get(f"{always_busy.http}/metrics").text
        assert 'lipstream_busy_refusals_total{reason="loop_busy"} 1.0' in metrics
        assert always_busy.state.overload.policy.upgrades == {}  # nothing counted as admitted
    finally:
        loop.accept_gate = recording.gate


def test_an_upgrade_past_its_addresss_rate_is_refused_at_accept(lerp_dir: Path) -> None:
    settings = ServerSettings(client_upgrade_rate=0.001, client_upgrade_burst=1)
    with serving(lerp_dir, settings) as served:
        loop = served.loop
        assert isinstance(loop, BoundedAcceptLoop)
        recording = Recording(loop.accept_gate)  # type: ignore[arg-type]
        loop.accept_gate = recording
        with client(served.ws):  # takes the address's one token
            pass
        assert recording.answers == [("127.0.0.1", None)]
        answer = sent_while_the_loop_waits(served, UPGRADE_HEAD)
        head, _, body = answer.partition(b"\r\n\r\n")
        assert head.startswith(b"HTTP/1.1 503 ")
        error = json.loads(body)["error"]
        assert (error["code"], error["details"]["reason"]) == (
            TOO_MANY_CLIENT_CONNECTIONS,
            "upgrade_rate",
        )
        assert recording.answers[-1][1] is not None  # answered by the gate
        probe = sent_while_the_loop_waits(
            served, b"GET /healthz HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n"
        )
        assert probe.startswith(b"HTTP/1.1 200 ")
