"""BoundedAcceptLoop drains the kernel's queue of new connections (up to SCAN_PER_TURN a
turn) into a waiting queue of its own, answers the ones its gate answers on the bare socket
at once, and starts at most ACCEPTS_PER_TURN protocols a turn (plus a filling queue's
excess), where asyncio's own loop starts a protocol for every queued connection at once.
Counted on a real listening socket, one loop iteration at a time."""

from __future__ import annotations

import asyncio
import json
import socket
import threading
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import httpx
import pytest

import lipstream.server.accept_loop as accept_loop
from lipstream.config import ServerSettings
from lipstream.server.accept_gate import (
    HEALTHZ_RESPONSE,
    ServerGate,
    is_health_probe,
    is_stream_upgrade,
)
from lipstream.server.accept_loop import (
    ACCEPTS_PER_TURN,
    LOOP,
    SCAN_PER_TURN,
    SLICE_S,
    AcceptGate,
    BoundedAcceptLoop,
    SlicedReady,
)
from lipstream.server.handshake import CLIENT_PROBE_LANE
from lipstream.server.runner import uvicorn_options
from lipstream_client.errors import TOO_MANY_CLIENT_CONNECTIONS
from tests.lipstream.server.harness import Served, client, serving

PENDING = 40
ANSWER = b"HTTP/1.1 503 Service Unavailable\r\ncontent-length: 0\r\n\r\n"
REFUSE_ME = b"refuse"
PROBE = b"GET /healthz HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n"


@contextmanager
def pending_connections(
    said: list[bytes], backlog: int = 4096
) -> Iterator[tuple[socket.socket, list[socket.socket]]]:
    """A listening loopback socket with one connection waiting to be accepted for each of
    ``said``, each having sent those bytes, and their client ends."""
    with ExitStack() as stack:
        listener = stack.enter_context(socket.socket())
        listener.bind(("127.0.0.1", 0))
        listener.listen(backlog)
        clients = []
        for data in said:
            client = stack.enter_context(socket.socket())
            client.connect(listener.getsockname())
            if data:
                client.sendall(data)
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
class ByWhatTheySaid:
    """A gate answering the connections that sent ``REFUSE_ME`` with ``ANSWER``, and health
    probes with ``HEALTHZ_RESPONSE``."""

    asked: int = 0

    def answer(self, connection: socket.socket, address: str) -> bytes | None:
        self.asked += 1
        try:
            sent = connection.recv(1024, socket.MSG_PEEK)
        except BlockingIOError:
            return None
        if sent == REFUSE_ME:
            return ANSWER
        return HEALTHZ_RESPONSE if sent == PROBE else None


def readiness(loop: BoundedAcceptLoop, listener: socket.socket, factory: object) -> None:
    """The listening socket's readiness callback, as the selector would run it."""
    loop._accept_connection(factory, listener, None, None, 4096)


@pytest.fixture
def unsliced(monkeypatch: pytest.MonkeyPatch) -> None:
    """Turns that run every ready callback, as asyncio's do: counting protocols per turn
    must not depend on how fast the machine builds them."""
    monkeypatch.setattr(accept_loop, "SLICE_S", float("inf"))


def turns(loop: BoundedAcceptLoop, built: Built, count: int) -> list[int]:
    """Run ``count`` iterations of the loop; the protocols built after each."""
    after = []
    for _ in range(count):
        loop.stop()
        loop.run_forever()  # one iteration: the selector polled once, the ready callbacks
        after.append(len(built.protocols))
    return after


def close(loop: BoundedAcceptLoop) -> None:
    """Let every waiting connection's protocol start, then close the loop."""
    for _ in range(100):
        loop.stop()
        loop.run_forever()
        if not loop.waiting and not loop._ready:
            break
    loop.close()


def received(client: socket.socket) -> bytes:
    client.settimeout(5.0)
    data = b""
    while chunk := client.recv(4096):
        data += chunk
    return data


@pytest.mark.usefixtures("unsliced")
def test_the_kernels_queue_is_drained_and_protocols_started_sixteen_a_turn() -> None:
    loop = BoundedAcceptLoop()
    built = Built()
    try:
        with pending_connections([b""] * PENDING) as (listener, _):
            readiness(loop, listener, built)
            assert still_queued(listener) == 0
            after = turns(loop, built, 8)
        steps = [later - earlier for earlier, later in zip([0, *after], after, strict=False)]
        assert max(steps) == ACCEPTS_PER_TURN and after[-1] == PENDING
        assert steps.count(ACCEPTS_PER_TURN) == PENDING // ACCEPTS_PER_TURN
        # asyncio's own loop starts every one in the same callback.
        plain = asyncio.SelectorEventLoop()
        plain_built = Built()
        with pending_connections([b""] * PENDING) as (listener, _):
            plain._accept_connection(plain_built, listener, None, None, 4096)  # type: ignore[attr-defined]
            plain.stop()
            plain.run_forever()
            assert len(plain_built.protocols) == PENDING
        plain.close()
    finally:
        close(loop)


def test_one_turn_scans_at_most_its_bound_and_the_waiting_queue_is_bounded(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    loop = BoundedAcceptLoop()
    try:
        with pending_connections([b""] * (SCAN_PER_TURN + 8)) as (listener, _):
            readiness(loop, listener, Built())
            assert len(loop.waiting) == SCAN_PER_TURN and still_queued(listener) == 8
    finally:
        close(loop)
    monkeypatch.setattr(accept_loop, "MAX_WAITING", 20)
    loop = BoundedAcceptLoop()
    try:
        with pending_connections([b""] * PENDING) as (listener, _):
            readiness(loop, listener, Built())
            assert len(loop.waiting) == 20 and still_queued(listener) == PENDING - 20
    finally:
        close(loop)


@pytest.mark.usefixtures("unsliced")
def test_a_queue_over_half_full_has_its_excess_started_in_the_next_turn() -> None:
    # 60 queued of 64: the bound and the 28 beyond half the queue.
    for pending, first_turn in ((60, ACCEPTS_PER_TURN + 60 - 32), (30, ACCEPTS_PER_TURN)):
        loop = BoundedAcceptLoop()
        built = Built()
        try:
            with pending_connections([b""] * pending, backlog=64) as (listener, _):
                readiness(loop, listener, built)
                assert turns(loop, built, 2)[-1] == first_turn
        finally:
            close(loop)


@pytest.mark.usefixtures("unsliced")
def test_the_gates_answers_are_given_at_once_without_a_protocol() -> None:
    loop = BoundedAcceptLoop()
    gate = ByWhatTheySaid()
    loop.accept_gate = gate
    built = Built()
    said = [REFUSE_ME if index % 2 else b"" for index in range(PENDING)]
    try:
        with pending_connections(said) as (listener, clients):
            readiness(loop, listener, built)
            assert built.protocols == [] and gate.asked == PENDING
            for client in clients[1::2]:
                assert received(client) == ANSWER  # then closed
            assert turns(loop, built, 4)[-1] == PENDING // 2
    finally:
        close(loop)


def test_a_probe_behind_a_flood_is_answered_in_the_first_turn() -> None:
    """The regression the waiting queue exists for: a probe queued behind hundreds of
    connections that will get protocols is answered in the readiness callback that accepts
    it, while those connections are still waiting for theirs."""
    loop = BoundedAcceptLoop()
    loop.accept_gate = ByWhatTheySaid()
    built = Built()
    flood = 200
    try:
        with pending_connections([b""] * flood + [PROBE]) as (listener, clients):
            readiness(loop, listener, built)
            assert received(clients[-1]) == HEALTHZ_RESPONSE
            assert built.protocols == [] and len(loop.waiting) == flood
    finally:
        close(loop)


@pytest.mark.usefixtures("unsliced")
def test_a_connection_is_asked_about_again_when_its_turn_comes() -> None:
    loop = BoundedAcceptLoop()
    gate = ByWhatTheySaid()
    loop.accept_gate = gate
    built = Built()
    try:
        with pending_connections([b""] * 3) as (listener, clients):
            readiness(loop, listener, built)
            clients[1].sendall(REFUSE_ME)  # said after it was accepted, before its protocol
            assert gate.asked == 3
            turns(loop, built, 2)
            assert len(built.protocols) == 2 and gate.asked == 6
            assert received(clients[1]) == ANSWER
    finally:
        close(loop)


def test_a_closing_listener_closes_its_waiting_connections() -> None:
    loop = BoundedAcceptLoop()
    try:
        with pending_connections([b""] * 3) as (listener, clients):
            readiness(loop, listener, Built())
            assert len(loop.waiting) == 3
            loop._stop_serving(listener)
            assert not loop.waiting and listener.fileno() == -1
            for client in clients:
                client.settimeout(5.0)
                try:
                    assert client.recv(16) == b""
                except ConnectionResetError:
                    pass
    finally:
        close(loop)


@dataclass
class FakeClock:
    now: float = 100.0

    def perf_counter(self) -> float:
        return self.now


def test_the_ready_queue_hands_out_callbacks_only_within_the_slice() -> None:
    loop = BoundedAcceptLoop()
    try:
        ready = SlicedReady(loop._ready.skip)
        first, second, third = (asyncio.Handle(print, (), loop) for _ in range(3))
        ready.extend([first, second, third])
        assert ready.popleft() is first  # no poll yet: no slice
        ready.slice_ends = 0.0  # long past
        assert ready.popleft() is ready.skip and ready.skip.cancelled()
        assert list(ready) == [second, third]
        ready.slice_ends = float("inf")
        assert [ready.popleft(), ready.popleft()] == [second, third]
        with pytest.raises(IndexError):
            ready.popleft()  # empty, as a deque
    finally:
        loop.close()


def test_a_turn_runs_callbacks_for_one_slice_then_polls_and_keeps_their_order(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    clock = FakeClock()
    monkeypatch.setattr(time, "perf_counter", clock.perf_counter)
    loop = BoundedAcceptLoop()
    ran: list[int] = []
    step = 0.4 * SLICE_S  # each callback takes 40% of a slice on the fake clock

    def work(index: int) -> None:
        ran.append(index)
        clock.now += step

    try:
        for index in range(7):
            loop.call_soon(work, index)
        per_turn = []
        for _ in range(4):
            loop.stop()
            loop.run_forever()
            per_turn.append(len(ran))
        # Three fit in a slice (at 0, 0.4 and 0.8 of it); the fourth waits for the next poll.
        assert per_turn == [3, 6, 7, 7] and ran == list(range(7))
    finally:
        loop.close()


def test_a_listening_sockets_readiness_runs_before_the_queued_callbacks() -> None:
    loop = BoundedAcceptLoop()
    order: list[str] = []

    class Recorder:
        def answer(self, connection: socket.socket, address: str) -> bytes | None:
            order.append("accept")
            return ANSWER

    loop.accept_gate = Recorder()
    try:
        with pending_connections([b""]) as (listener, clients):
            loop._start_serving(Built(), listener)
            for name in "abc":
                loop.call_soon(order.append, name)
            loop.stop()
            loop.run_forever()
            assert order == ["accept", "a", "b", "c"]
            assert received(clients[0]) == ANSWER
            loop._stop_serving(listener)
            assert listener.fileno() == -1 and not loop.listening
    finally:
        close(loop)


def test_a_health_probe_is_told_from_a_whole_head() -> None:
    assert is_health_probe(PROBE)
    assert is_health_probe(b"GET /healthz?verbose=1 HTTP/1.0\r\n\r\n")
    assert not is_health_probe(PROBE[:-2])  # the head is not complete yet
    assert not is_health_probe(PROBE + b"GET /healthz HTTP/1.1\r\n\r\n")  # pipelined
    assert not is_health_probe(PROBE.replace(b"/healthz", b"/healthzz"))
    assert not is_health_probe(PROBE.replace(b"/healthz", b"/readyz"))
    assert not is_health_probe(PROBE.replace(b"GET ", b"POST "))
    assert not is_health_probe(PROBE.replace(b"HTTP/1.1", b"HTTP/2"))
    assert not is_health_probe(PROBE.replace(b"Host: x", b"Content-Length: 3"))
    assert HEALTHZ_RESPONSE.startswith(b"HTTP/1.1 200 OK\r\n")
    head, _, payload = HEALTHZ_RESPONSE.partition(b"\r\n\r\n")
    assert json.loads(payload) == {"status": "ok"}
    assert f"content-length: {len(payload)}".encode() in head


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

    def answer(self, connection: socket.socket, address: str) -> bytes | None:
        answer = self.gate.answer(connection, address)
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
        assert recording.answers[-1][0] == "127.0.0.1"
        assert recording.answers[-1][1] in (None, HEALTHZ_RESPONSE)
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
    holding, release = threading.Event(), threading.Event()

    async def hold() -> None:
        holding.set()
        release.wait(timeout=30)

    held = served.call_soon(hold())
    assert holding.wait(timeout=30)  # the loop is held before the client connects
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
        assert probe == HEALTHZ_RESPONSE == recording.answers[-1][1]  # answered at accept
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
        assert recording.answers and set(recording.answers) == {("127.0.0.1", None)}
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
