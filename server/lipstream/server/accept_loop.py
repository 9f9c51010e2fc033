"""The event loop the server runs on: asyncio's, polling for I/O at least every
``SLICE_S`` of callbacks with new connections first, draining the kernel's queue of new
connections into a queue of its own, answering at once the connections that need no
protocol, and starting a bounded number of protocols per turn.

Sketch: when the listening socket is readable, asyncio accepts connections in a loop, up to
the listen backlog in one callback, and schedules every one's ``connection_made`` at
once; in a storm of connections the heads, upgrades and refusals of hundreds then run before
the loop turns back to the sessions it serves, one stall of hundreds of milliseconds.
Leaving them in the kernel's queue instead (a bound per turn) keeps the turns short, but
that queue is first in, first out: a health probe that arrives behind a client's flood of
connections waits for all of them. ``BoundedAcceptLoop`` takes up to ``SCAN_PER_TURN``
connections from the kernel's queue per readiness callback and asks its ``AcceptGate``
(``accept_gate.ServerGate``) about each: one that can be answered whole without a protocol
(a health probe whose head has arrived; a connection the server refuses outright, such as
an address over its limits or a WebSocket upgrade while the load verdict refuses sessions)
is answered and closed there, on the bare socket, in a few microseconds; the others join
the loop's own *waiting* queue, of at most ``MAX_WAITING``. Once per turn, after the
sessions' own I/O, at most ``ACCEPTS_PER_TURN`` waiting connections get their protocols,
each asked about again first (an address's count or the load verdict may have moved since).
A kernel queue left to fill drops the SYNs of every newcomer, probes included (they are
retried only after 1 s, then 3 s), so while it leaves less than ``QUEUE_HEADROOM`` places
free (Linux reports its length and capacity for a listening socket in ``TCP_INFO``) a turn
also takes the excess. uvicorn builds the loop from the import string ``LOOP`` (its ``loop``
setting), in every worker; the server installs its gate when it goes live.

A turn of asyncio's loop polls once and then runs every callback that was ready: under
load, a hundred or more sessions' messages, 100–300 ms of the core when a pool thread
shares it, and a connection that arrives meanwhile waits for the whole turn and then for
its place behind the next one's. So the loop's ready queue (``SlicedReady``) hands out
callbacks only until ``SLICE_S`` has passed since the poll; the rest stay queued, in order,
and run after the next poll (asyncio polls without waiting while callbacks are ready), and
a listening socket's readiness goes to the front of the queue. A health probe is then
answered within about one slice however long the queued work is, and the order in which
the loop runs everything else is asyncio's own.
"""

from __future__ import annotations

import asyncio
import selectors
import socket
import struct
import time
from collections import deque
from typing import Any, NamedTuple, Protocol

SLICE_S = 0.005
ACCEPTS_PER_TURN = 16
SCAN_PER_TURN = 256
MAX_WAITING = 1024
QUEUE_HEADROOM = 256
LOOP = "lipstream.server.accept_loop:BoundedAcceptLoop"
TCP_INFO_QUEUE = struct.Struct("8x16xII")  # tcpi_unacked, tcpi_sacked: queued, capacity
READ_BEFORE_CLOSE = 65536


class AcceptGate(Protocol):
    """Which accepted connections get their whole answer at once, without a protocol."""

    def answer(self, connection: socket.socket, address: str) -> bytes | None:
        """The whole HTTP answer for the fresh ``connection`` from ``address`` (it may peek
        at what the client sent), or None to serve it."""
        ...


class Waiting(NamedTuple):
    """An accepted connection waiting for its protocol, with what asyncio needs to build it."""

    connection: socket.socket
    address: Any
    listener: socket.socket
    protocol_factory: Any
    sslcontext: Any
    server: Any
    options: tuple[Any, ...]


def _skipped() -> None:
    pass


class SlicedReady(deque[asyncio.Handle]):
    """An event loop's ready queue that hands out callbacks until ``slice_ends``
    (``time.perf_counter``), and after it a cancelled handle, which the loop skips, leaving
    the queue as it is: asyncio's turn runs as many callbacks as were ready at its start,
    taking each from the left, and skips cancelled ones."""

    def __init__(self, skip: asyncio.Handle) -> None:
        super().__init__()
        self.skip = skip
        self.slice_ends = float("inf")

    def popleft(self) -> asyncio.Handle:
        if time.perf_counter() > self.slice_ends and self:
            return self.skip
        return super().popleft()


def queue_excess(sock: socket.socket) -> int:
    """How many connections the listening ``sock``'s queue holds beyond its capacity less
    ``QUEUE_HEADROOM`` (at most half of it); 0 where the kernel does not say."""
    try:
        info = sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_INFO, TCP_INFO_QUEUE.size)
        queued, capacity = TCP_INFO_QUEUE.unpack(info)
    except (AttributeError, OSError, struct.error):
        return 0
    return max(0, int(queued) - max(int(capacity) - QUEUE_HEADROOM, int(capacity) // 2))


def answer_and_close(connection: socket.socket, answer: bytes) -> None:
    """Send ``answer`` on a fresh non-blocking connection and close it. What the client
    already sent is read first: closing with unread bytes would send a reset, which can
    destroy the answer before the client reads it."""
    try:
        connection.recv(READ_BEFORE_CLOSE)
    except OSError:
        pass
    try:
        connection.send(answer)
    except OSError:
        pass
    connection.close()


class BoundedAcceptLoop(asyncio.SelectorEventLoop):
    """asyncio's selector loop, answering the ``accept_gate``'s connections itself and
    starting at most ``ACCEPTS_PER_TURN`` protocols per turn (plus a filling queue's
    excess)."""

    accept_gate: AcceptGate | None = None

    def __init__(self, selector: Any = None) -> None:
        super().__init__(selector)
        skip = asyncio.Handle(_skipped, (), self)
        skip.cancel()
        self._ready: SlicedReady = SlicedReady(skip)
        self.listening: set[int] = set()
        self.waiting: deque[Waiting] = deque()
        self.extra_accepts = 0
        self.start_scheduled = False

    def _process_events(self, event_list: list[tuple[selectors.SelectorKey, int]]) -> None:
        """After each poll: a new slice, and a listening socket's readiness first."""
        self._ready.slice_ends = time.perf_counter() + SLICE_S
        listeners = [event for event in event_list if event[0].fd in self.listening]
        if listeners:
            others = [event for event in event_list if event[0].fd not in self.listening]
            queued = len(self._ready)
            super()._process_events(listeners)  # type: ignore[misc]
            for _ in range(len(self._ready) - queued):
                self._ready.appendleft(self._ready.pop())
            event_list = others
        super()._process_events(event_list)  # type: ignore[misc]

    def _start_serving(self, protocol_factory: Any, sock: socket.socket, *args: Any) -> None:
        self.listening.add(sock.fileno())
        super()._start_serving(protocol_factory, sock, *args)  # type: ignore[misc]

    def _accept_connection(
        self,
        protocol_factory: Any,
        sock: socket.socket,
        sslcontext: Any = None,
        server: Any = None,
        backlog: int = 100,
        *options: Any,
    ) -> None:
        excess = queue_excess(sock)
        self.extra_accepts = max(self.extra_accepts, excess)
        for _ in range(SCAN_PER_TURN + excess):
            if len(self.waiting) >= MAX_WAITING + excess:
                break
            try:
                connection, address = sock.accept()
                connection.setblocking(False)
            except (BlockingIOError, InterruptedError, ConnectionAbortedError):
                break
            except OSError:
                # Out of descriptors or memory: asyncio's own accept meets the same error
                # and pauses accepting for a while.
                super()._accept_connection(  # type: ignore[misc]
                    protocol_factory, sock, sslcontext, server, 1, *options
                )
                break
            if not self._answered(connection, address):
                self.waiting.append(
                    Waiting(
                        connection, address, sock, protocol_factory, sslcontext, server, options
                    )
                )
        self._schedule_starts()

    def _answered(self, connection: socket.socket, address: Any) -> bool:
        gate = self.accept_gate
        if gate is None or not isinstance(address, tuple):
            return False
        answer = gate.answer(connection, address[0])
        if answer is None:
            return False
        answer_and_close(connection, answer)
        return True

    def _schedule_starts(self) -> None:
        if self.waiting and not self.start_scheduled:
            self.start_scheduled = True
            self.call_soon(self._start_protocols)

    def _start_protocols(self) -> None:
        self.start_scheduled = False
        budget = ACCEPTS_PER_TURN + self.extra_accepts
        self.extra_accepts = 0
        started = 0
        while self.waiting and started < budget:
            waiting = self.waiting.popleft()
            if self._answered(waiting.connection, waiting.address):
                continue
            started += 1
            self.create_task(
                self._accept_connection2(  # type: ignore[attr-defined]
                    waiting.protocol_factory,
                    waiting.connection,
                    {"peername": waiting.address},
                    waiting.sslcontext,
                    waiting.server,
                    *waiting.options,
                )
            )
        self._schedule_starts()

    def close(self) -> None:
        while self.waiting:
            self.waiting.popleft().connection.close()
        super().close()

    def _stop_serving(self, sock: socket.socket) -> None:
        """A listener closing: its connections still waiting are closed with it, as the
        kernel resets those still in its queue."""
        kept = deque(waiting for waiting in self.waiting if waiting.listener is not sock)
        for waiting in self.waiting:
            if waiting.listener is sock:
                waiting.connection.close()
        self.waiting = kept
        self.listening.discard(sock.fileno())
        super()._stop_serving(sock)  # type: ignore[misc]
