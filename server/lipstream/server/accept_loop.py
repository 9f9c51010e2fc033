"""The event loop the server runs on: asyncio's, taking a bounded number of new connections
per turn, more while the kernel's queue fills, and answering the connections the server
refuses outright before any protocol is built.

Sketch: when the listening socket is readable, asyncio accepts connections in a loop, up to
the listen backlog in one callback, and schedules every one's ``connection_made`` at
once; in a storm of connections the heads, upgrades and refusals of hundreds then run before
the loop turns back to the sessions it serves, one stall of hundreds of milliseconds.
``BoundedAcceptLoop`` takes at most ``ACCEPTS_PER_TURN`` per readiness callback; the rest
wait in the kernel's queue, and the selector reports the socket readable again on the next
turn, after the sessions' own I/O. A queue left to fill drops the SYNs of every newcomer,
health probes included (they are retried only after 1 s, then 3 s), so while the queue
leaves less than ``QUEUE_HEADROOM`` places free (Linux reports its length and capacity for
a listening socket in ``TCP_INFO``) a turn also takes the excess: taken sooner, a storm's
excess would be one long turn of handshakes. A connection the server would refuse outright
(``AcceptGate``, ``accept_gate.ServerGate``: an address over its limits, a WebSocket upgrade
while the load verdict refuses sessions) is answered and closed here, on the bare socket:
no transport, no protocol, no task. Those cost a few microseconds each, so up to
``REFUSALS_PER_TURN`` of them are taken in a turn beside the bound. uvicorn builds the loop
from the import string ``LOOP`` (its ``loop`` setting), in every worker; the server installs
its gate when it goes live.
"""

from __future__ import annotations

import asyncio
import socket
import struct
from typing import Any, Protocol

ACCEPTS_PER_TURN = 16
REFUSALS_PER_TURN = 128
QUEUE_HEADROOM = 256
LOOP = "lipstream.server.accept_loop:BoundedAcceptLoop"
TCP_INFO_QUEUE = struct.Struct("8x16xII")  # tcpi_unacked, tcpi_sacked: queued, capacity
READ_BEFORE_CLOSE = 65536


class AcceptGate(Protocol):
    """Which accepted connections get an answer at once, without a protocol."""

    def refusal(self, connection: socket.socket, address: str) -> bytes | None:
        """The whole HTTP answer for the fresh ``connection`` from ``address`` (it may peek
        at what the client sent), or None to serve it."""
        ...


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
    """asyncio's selector loop, accepting at most ``ACCEPTS_PER_TURN`` connections per turn
    (plus a filling queue's excess), and answering the ``accept_gate``'s refusals itself."""

    accept_gate: AcceptGate | None = None

    def _accept_connection(
        self,
        protocol_factory: Any,
        sock: socket.socket,
        sslcontext: Any = None,
        server: Any = None,
        backlog: int = 100,
        *args: Any,
        **kwargs: Any,
    ) -> None:
        budget = min(backlog, ACCEPTS_PER_TURN + queue_excess(sock))
        accepted = refused = 0
        while accepted < budget and refused < REFUSALS_PER_TURN:
            try:
                connection, address = sock.accept()
                connection.setblocking(False)
            except (BlockingIOError, InterruptedError, ConnectionAbortedError):
                return
            except OSError:
                # Out of descriptors or memory: asyncio's own accept meets the same error
                # and pauses accepting for a while.
                super()._accept_connection(  # type: ignore[misc]
                    protocol_factory, sock, sslcontext, server, 1, *args, **kwargs
                )
                return
            gate = self.accept_gate
            answer = None
            if gate is not None and isinstance(address, tuple):
                answer = gate.refusal(connection, address[0])
            if answer is not None:
                answer_and_close(connection, answer)
                refused += 1
                continue
            accepted += 1
            extra = {"peername": address}
            self.create_task(
                self._accept_connection2(  # type: ignore[attr-defined]
                    protocol_factory, connection, extra, sslcontext, server, *args, **kwargs
                )
            )
