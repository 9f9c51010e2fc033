"""The accept loop's gate: connections answered whole on the bare socket before any protocol
is built, health probes and the connections the server refuses outright.

Sketch: a ``GET /healthz`` whose whole head has arrived (read with ``MSG_PEEK``) gets its
``200 {"status":"ok"}`` and is closed, from any address and at any load, as the protocol
would answer it: a probe then never waits behind a flood's connections for a protocol of
its own. Three kinds of connection get an HTTP 503 from the HTTP protocol before it reads
anything more than their head (``handshake``): one from an address at its connection cap
with its probe lane full, a WebSocket upgrade to ``/v1/stream`` from an address out of
upgrade tokens (both ``too_many_client_connections``), and such an upgrade while the load
verdict refuses new sessions or the loop sheds (``server_busy``). Building the protocol,
parsing the head with h11 and tearing the connection down cost the loop most of a
millisecond each, so a storm's refusals alone keep it saturated for as long as the storm
lasts. ``ServerGate`` gives the same answers a
step earlier, in the accept loop (``accept_loop.AcceptGate``): the address's count is a
lookup, and an upgrade is told from its head read with ``MSG_PEEK`` (a head not yet
complete, or any other request, goes on to the protocol). The
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
    HEALTHZ_BODY,
    HEALTHZ_PATH,
    MAX_HEAD_BYTES,
    SHEDDING,
    STREAM_PATH,
    busy_response,
)
from .state import ServerState

UPGRADE_FIELD = re.compile(rb"^upgrade:[ \t]*websocket[ \t]*\r?$", re.IGNORECASE | re.MULTILINE)
STREAM_TARGET = STREAM_PATH.encode()
HEALTHZ_TARGET = HEALTHZ_PATH.encode()
BODY_FIELD = re.compile(rb"^(content-length|transfer-encoding):", re.IGNORECASE | re.MULTILINE)
HEALTHZ_RESPONSE = (
    b"HTTP/1.1 200 OK\r\ncontent-type: application/json\r\n"
    b"content-length: "
    + str(len(HEALTHZ_BODY)).encode()
    + b"\r\nconnection: close\r\n\r\n"
    + HEALTHZ_BODY
)


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


def is_health_probe(head: bytes) -> bool:
    """Whether ``head``, the bytes a client has sent so far, are exactly one whole
    ``GET /healthz`` request without a body."""
    whole, complete, rest = head.partition(b"\r\n\r\n")
    if not complete or rest:
        return False
    line, _, fields = whole.partition(b"\r\n")
    parts = line.split(b" ")
    return (
        len(parts) == 3
        and parts[0] == b"GET"
        and parts[1].split(b"?", 1)[0] == HEALTHZ_TARGET
        and parts[2] in (b"HTTP/1.0", b"HTTP/1.1")
        and not BODY_FIELD.search(fields)
    )


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
    def sent(self) -> bytes:
        return peeked_head(self.connection)

    @property
    def is_upgrade(self) -> bool:
        return is_stream_upgrade(self.sent)

    @property
    def is_health_probe(self) -> bool:
        return is_health_probe(self.sent)


@dataclass
class ServerGate:
    """The answers the HTTP protocol would give before reading further, given at accept."""

    server: ServerState

    def answer(self, connection: socket.socket, address: str) -> bytes | None:
        server = self.server
        metrics = server.metrics
        head = Head(connection)
        if head.is_health_probe:
            return HEALTHZ_RESPONSE
        if server.clients.saturated(address, CLIENT_PROBE_LANE):
            metrics.labelled(metrics.refused, TOO_MANY_CLIENT_CONNECTIONS).inc()
            metrics.labelled(metrics.client_refusals, CONNECTIONS).inc()
            return refusal_response(server.clients, address, CONNECTIONS)
        if server.lifecycle.draining:
            return None
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
