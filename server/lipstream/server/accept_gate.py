"""The accept loop's gate: connections the server refuses outright, answered on the bare
socket before any protocol is built.

Sketch: three kinds of connection get an HTTP 503 from the HTTP protocol before it reads
anything more than their head (``handshake``): one from an address at its connection cap
with its probe lane full, a WebSocket upgrade to ``/v1/stream`` from an address out of
upgrade tokens (both ``too_many_client_connections``), and such an upgrade while the load
verdict refuses new sessions or the loop sheds (``server_busy``). Building the protocol,
parsing the head with h11 and tearing the connection down cost the loop most of a
millisecond each, so a storm's refusals alone keep it saturated for as long as the storm
lasts. ``ServerGate`` gives the same answers a
step earlier, in the accept loop (``accept_loop.AcceptGate``): the address's count is a
lookup, and an upgrade is told from its head read with ``MSG_PEEK`` (a head not yet
complete, or any other request, such as a health probe, goes on to the protocol). The
load verdict is taken without counting anything (``Overload.verdict``); an upgrade it
would admit is admitted, and counted, by the protocol as before. Answers are counted in
the same metrics as the protocol's.
"""

from __future__ import annotations

import asyncio
import re
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property

from lipstream_client.errors import SERVER_BUSY, TOO_MANY_CLIENT_CONNECTIONS

from .accept_loop import BoundedAcceptLoop
from .client_limits import CONNECTIONS, UPGRADE_RATE, refusal_response
from .handshake import (
    BUSY_RESPONSE,
    CLIENT_PROBE_LANE,
    MAX_HEAD_BYTES,
    SHEDDING,
    STREAM_PATH,
    busy_response,
)
from .state import ServerState

UPGRADE_FIELD = re.compile(rb"^upgrade:[ \t]*websocket[ \t]*\r?$", re.IGNORECASE | re.MULTILINE)
STREAM_TARGET = STREAM_PATH.encode()


def is_stream_upgrade(head: bytes) -> bool:
    """Whether ``head``, the bytes a client has sent so far, hold a whole request head that
    asks to upgrade ``/v1/stream`` to a WebSocket."""
    whole, complete, _ = head.partition(b"\r\n\r\n")
    if not complete:
        return False
    line, _, fields = whole.partition(b"\r\n")
    parts = line.split(b" ")
    if len(parts) != 3 or parts[0] != b"GET":
        return False
    return parts[1].split(b"?", 1)[0] == STREAM_TARGET and bool(UPGRADE_FIELD.search(fields))


def peeked_head(connection: socket.socket) -> bytes:
    """What the client has sent so far, left unread."""
    try:
        return connection.recv(MAX_HEAD_BYTES + 4, socket.MSG_PEEK)
    except OSError:
        return b""


class Head:
    """A fresh connection's head, peeked at most once, when first asked about."""

    def __init__(self, connection: socket.socket) -> None:
        self.connection = connection

    @cached_property
    def is_upgrade(self) -> bool:
        return is_stream_upgrade(peeked_head(self.connection))


@dataclass
class ServerGate:
    """The refusals the HTTP protocol would make before reading further, made at accept."""

    server: ServerState

    def refusal(self, connection: socket.socket, address: str) -> bytes | None:
        server = self.server
        metrics = server.metrics
        if server.clients.saturated(address, CLIENT_PROBE_LANE):
            metrics.labelled(metrics.refused, TOO_MANY_CLIENT_CONNECTIONS).inc()
            metrics.labelled(metrics.client_refusals, CONNECTIONS).inc()
            return refusal_response(server.clients, address, CONNECTIONS)
        if server.lifecycle.draining:
            return None
        head = Head(connection)
        if server.clients.out_of_upgrades(address, time.monotonic()) and head.is_upgrade:
            metrics.labelled(metrics.refused, TOO_MANY_CLIENT_CONNECTIONS).inc()
            metrics.labelled(metrics.client_refusals, UPGRADE_RATE).inc()
            return refusal_response(server.clients, address, UPGRADE_RATE)
        sessions = len(server.lifecycle.connections)
        if server.overload.shedding(sessions):
            if not head.is_upgrade:
                return None
            metrics.labelled(metrics.refused, SHEDDING).inc()
            return BUSY_RESPONSE
        busy = server.overload.verdict(sessions)
        if busy is None or not head.is_upgrade:
            return None
        metrics.labelled(metrics.refused, SERVER_BUSY).inc()
        metrics.labelled(metrics.busy_refusals, busy.reason).inc()
        return busy_response(busy)


def install_server_gate(server: ServerState) -> Callable[[], None]:
    """Put the gate on the running loop when it is a ``BoundedAcceptLoop``; the callable
    takes it off."""
    loop = asyncio.get_running_loop()
    if not isinstance(loop, BoundedAcceptLoop):
        return lambda: None
    loop.accept_gate = ServerGate(server)

    def remove() -> None:
        loop.accept_gate = None

    return remove
