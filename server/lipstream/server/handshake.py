"""Connections before their request head: a deadline for it, a cap on open connections, and
``/healthz`` answered before the app.

Sketch: uvicorn's HTTP protocol arms no timer until a first response is sent, so a client
that opens a socket and says nothing, or sends half a request head, holds a file descriptor
and a protocol object for good: enough of them exhaust the process's descriptors, and then
no connection, not even a health probe, gets in. ``GuardedHTTPProtocol`` (uvicorn's HTTP
protocol with ``http_flush``'s bound on unsent bytes) adds:

- a *head deadline*: ``LIPSTREAM_HANDSHAKE_TIMEOUT_S`` from when the connection opens, and
  again from the end of each response unless a pipelined request is already under way, the
  client must have completed a request head (a request or a WebSocket upgrade), or the
  connection is closed. Reading a body and idling between requests are left to the app and
  to uvicorn's keep-alive timeout;
- a *connection cap*: uvicorn keeps every open connection of the worker in one set (HTTP,
  WebSocket, and those still sending their head). A connection that finds
  ``LIPSTREAM_MAX_CONNECTIONS`` (lowered to leave descriptors free, see ``open_files``)
  already open is *over the cap*: it may still send a request head within
  ``PROBE_HEAD_S``, and then ``GET /healthz`` is answered while any other request or upgrade
  gets HTTP 503 with ``Retry-After`` and ``Connection: close``, so a liveness probe passes
  while the worker holds as many connections as it can. At most ``PROBE_LANE`` connections
  wait over the cap at once; one beyond that gets the 503 at once and is closed, before the
  server reads anything from it;
- *per-client limits* (``client_limits``): a connection that finds its address holding
  ``LIPSTREAM_MAX_CLIENT_CONNECTIONS`` open connections is over that client's cap and is
  treated as one over the worker's cap (``/healthz`` answered within ``PROBE_HEAD_S``, at
  most ``CLIENT_PROBE_LANE`` of an address waiting at once), and a WebSocket upgrade beyond
  the address's ``LIPSTREAM_CLIENT_UPGRADE_RATE`` is refused too; both get HTTP 503 with
  ``too_many_client_connections`` in a JSON error body, ``Retry-After`` and
  ``Connection: close``, so one client cannot fill the worker's cap for everyone else;
- *admission at the upgrade*: a WebSocket upgrade to ``/v1/stream`` is admitted or refused
  for load (``overload``: memory, lag, the loop's CPU) as soon as its head is parsed; a
  refused one gets HTTP 503 with the ``server_busy`` error (``details.reason``,
  ``details.retry_after_ms``) as its JSON body, ``Retry-After`` and ``Connection: close``,
  so a storm's refusals cost no WebSocket handshake, no app task and no close handshake, and
  an admitted one counts against the next head at once. While the server drains, the
  endpoint answers instead (``shutting_down``);
- *shedding*: while the event loop lags far behind (``overload.OverloadPolicy.shedding``),
  a WebSocket upgrade gets a 503 at once, with no verdict and no WebSocket work;
- a *head size limit*: a request head (request line and header fields) of more than
  ``MAX_HEAD_BYTES`` gets HTTP 431 and the connection is closed, whether the head arrives
  whole (h11 parses any complete head) or in pieces (h11 stops buffering an incomplete one
  past the same size), and whether it asks for an upgrade or not. Once answered, what the
  client still sends is read and dropped until it stops, for at most ``LINGER_S`` or
  ``LINGER_BYTES``: closing a socket with unread bytes sends a TCP reset, which can
  destroy the answer before the client reads it;
- ``GET /healthz`` answered by a bare ASGI callable in front of the app: no routing, no
  middleware, no lifespan state, the cheapest answer the event loop can give.

Connections closed at the deadline, refused past the cap, refused past a client's limits,
refused for load, shed and refused for their head's size are counted in
``lipstream_connections_refused`` (codes ``handshake_timeout``, ``too_many_connections``,
``too_many_client_connections``, ``server_busy``, ``shedding`` and ``head_too_large``); a
client's refusals also in ``lipstream_client_refusals`` by reason, a refusal for load also in
``lipstream_busy_refusals`` by reason.
"""

from __future__ import annotations

import asyncio
import json
import weakref
from asyncio import Transport
from collections.abc import Mapping
from typing import Any

from uvicorn._types import (
    ASGI3Application,
    ASGIReceiveCallable,
    ASGISendCallable,
    HTTPScope,
    Scope,
)
from uvicorn.server import ServerState as UvicornState

from lipstream_client.errors import SERVER_BUSY

from .client_limits import (
    CONNECTIONS,
    UPGRADE_RATE,
    ClientLimits,
    refusal_body,
    refusal_headers,
    refusal_response,
)
from .http_flush import BoundedFlushHTTPProtocol
from .open_files import connection_cap, open_file_limit
from .overload import Refusal, Upgrade
from .startup import server_of

HANDSHAKE_TIMEOUT = "handshake_timeout"
TOO_MANY_CONNECTIONS = "too_many_connections"
SHEDDING = "shedding"
HEAD_TOO_LARGE = "head_too_large"
TOO_MANY_CLIENT_CONNECTIONS = "too_many_client_connections"
CLIENT_PROBE_LANE = 4
MAX_HEAD_BYTES = 16 * 1024  # h11's own bound on an incomplete head
LINGER_S = 2.0
LINGER_BYTES = 4 * 1024 * 1024
HEALTHZ_PATH = "/healthz"
STREAM_PATH = "/v1/stream"
HEALTHZ_BODY = json.dumps({"status": "ok"}, separators=(",", ":")).encode()
PROBE_LANE = 64
PROBE_HEAD_S = 1.0
RETRY_AFTER_S = 1
DEFAULT_HANDSHAKE_TIMEOUT_S = 10.0
DEFAULT_MAX_CONNECTIONS = 4096
BUSY_BODY = b"the server is at its capacity; retry later\n"
BUSY_HEADERS = [
    (b"content-type", b"text/plain; charset=utf-8"),
    (b"content-length", str(len(BUSY_BODY)).encode()),
    (b"retry-after", str(RETRY_AFTER_S).encode()),
    (b"connection", b"close"),
]
BUSY_RESPONSE = (
    b"HTTP/1.1 503 Service Unavailable\r\n"
    + b"".join(name + b": " + value + b"\r\n" for name, value in BUSY_HEADERS)
    + b"\r\n"
    + BUSY_BODY
)


def head_too_large(size: int) -> tuple[list[tuple[bytes, bytes]], bytes]:
    """The headers and body of HTTP 431 for a head of at least ``size`` bytes."""
    body = (
        f"the request head has at least {size} bytes, more than the limit of "
        f"{MAX_HEAD_BYTES} bytes\n"
    ).encode()
    headers = [
        (b"content-type", b"text/plain; charset=utf-8"),
        (b"content-length", str(len(body)).encode()),
        (b"connection", b"close"),
    ]
    return headers, body


def head_size(scope: HTTPScope) -> int:
    """The bytes of a parsed request head: its request line and header fields."""
    line = len(scope["method"]) + len(scope["raw_path"] or b"") + len(scope["query_string"])
    return line + 12 + sum(len(name) + len(value) + 4 for name, value in scope["headers"])


_over_cap: weakref.WeakKeyDictionary[UvicornState, set[GuardedHTTPProtocol]]
_over_cap = weakref.WeakKeyDictionary()


def refused(app_state: Mapping[str, Any], code: str) -> None:
    """Count a connection the protocol turned away (``lipstream_connections_refused``)."""
    server = server_of(app_state)
    if server is not None:
        server.metrics.labelled(server.metrics.refused, code).inc()


def shedding(app_state: Mapping[str, Any]) -> bool:
    """Whether the app's event loop lags too far behind for any WebSocket work
    (``overload.OverloadPolicy.shedding``)."""
    server = server_of(app_state)
    return server is not None and server.overload.shedding(len(server.lifecycle.connections))


def upgrade_refusal(app_state: Mapping[str, Any], client: tuple[str, int] | None) -> Refusal | None:
    """The load verdict on a WebSocket upgrade from ``client`` (None: admitted and pending as
    ``Upgrade(client)``, or not the app's to give yet: starting, draining, no address)."""
    server = server_of(app_state)
    if server is None or client is None or server.lifecycle.draining:
        return None
    busy = server.overload.upgrade_refusal(len(server.lifecycle.connections), Upgrade(client))
    if busy is not None:
        refused(app_state, SERVER_BUSY)
        server.metrics.labelled(server.metrics.busy_refusals, busy.reason).inc()
    return busy


def busy_response(refusal: Refusal) -> bytes:
    """The whole HTTP 503 answer to an upgrade refused for load."""
    error = {"code": refusal.code, "message": refusal.message, "details": refusal.details}
    body = json.dumps({"error": error}, separators=(",", ":")).encode()
    headers = [
        (b"content-type", b"application/json"),
        (b"content-length", str(len(body)).encode()),
        (b"retry-after", str(-(-refusal.retry_after_ms // 1000)).encode()),
        (b"connection", b"close"),
    ]
    return (
        b"HTTP/1.1 503 Service Unavailable\r\n"
        + b"".join(name + b": " + value + b"\r\n" for name, value in headers)
        + b"\r\n"
        + body
    )


def client_limits(app_state: Mapping[str, Any]) -> ClientLimits | None:
    """The per-client limits of the app whose lifespan state is ``app_state``."""
    server = server_of(app_state)
    return None if server is None else server.clients


def refused_client(app_state: Mapping[str, Any], reason: str) -> None:
    """Count a connection refused with ``too_many_client_connections``."""
    refused(app_state, TOO_MANY_CLIENT_CONNECTIONS)
    server = server_of(app_state)
    if server is not None:
        server.metrics.labelled(server.metrics.client_refusals, reason).inc()


def head_limits(app_state: Mapping[str, Any]) -> tuple[float, int]:
    """(handshake timeout in s, connection cap) of the app whose lifespan state is
    ``app_state``."""
    server = server_of(app_state)
    timeout, wanted = DEFAULT_HANDSHAKE_TIMEOUT_S, DEFAULT_MAX_CONNECTIONS
    if server is not None:
        timeout, wanted = server.settings.handshake_timeout_s, server.settings.max_connections
    return timeout, connection_cap(wanted, open_file_limit())


async def answer_healthz(
    scope: Scope, receive: ASGIReceiveCallable, send: ASGISendCallable
) -> None:
    headers = [
        (b"content-type", b"application/json"),
        (b"content-length", str(len(HEALTHZ_BODY)).encode()),
    ]
    await send({"type": "http.response.start", "status": 200, "headers": headers})
    await send({"type": "http.response.body", "body": HEALTHZ_BODY})


async def answer_busy(scope: Scope, receive: ASGIReceiveCallable, send: ASGISendCallable) -> None:
    await send({"type": "http.response.start", "status": 503, "headers": BUSY_HEADERS})
    await send({"type": "http.response.body", "body": BUSY_BODY})


class GuardedHTTPProtocol(BoundedFlushHTTPProtocol):
    """An HTTP connection with a deadline for its request head, under the connection cap."""

    def connection_made(self, transport: Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        self.head_timer: asyncio.TimerHandle | None = None
        self.over_cap = False
        self.lingering = 0  # bytes dropped after a 431, while lingering
        self.app_behind_gate = self.app
        self.app = self._route
        self.limits = client_limits(self.app_state)
        self.address = self.client[0] if self.client else ""
        self.over_client_cap = False
        self.client_waiting = False
        timeout, cap = head_limits(self.app_state)
        self.head_timeout_s = timeout
        if len(self.connections) > cap:
            waiting = _over_cap.setdefault(self.server_state, set())
            if len(waiting) >= PROBE_LANE:
                self._refuse(TOO_MANY_CONNECTIONS)
                return
            waiting.add(self)
            self.over_cap = True
            self.head_timeout_s = min(timeout, PROBE_HEAD_S)
        if self.limits is not None and self.address:
            if not self.limits.opened(self.address, self.loop.time()):
                if self.limits.wait(self.address) >= CLIENT_PROBE_LANE:
                    self.limits.done_waiting(self.address)
                    self._refuse_client(CONNECTIONS)
                    return
                self.client_waiting = self.over_client_cap = True
                self.head_timeout_s = min(self.head_timeout_s, PROBE_HEAD_S)
        self._arm_head_timer()

    def connection_lost(self, exc: Exception | None) -> None:
        super().connection_lost(exc)
        self._head_done()
        if self.limits is not None and self.address:
            self.limits.closed(self.address, self.loop.time())

    def on_response_complete(self) -> None:
        super().on_response_complete()
        cycle = self.cycle
        under_way = cycle is not None and not cycle.response_complete
        if not under_way and not self.transport.is_closing():
            self._arm_head_timer()

    def data_received(self, data: bytes) -> None:
        if self.lingering:
            self.lingering += len(data)
            if self.lingering > LINGER_BYTES:
                self.transport.close()
            return
        super().data_received(data)

    def eof_received(self) -> None:
        if self.lingering:
            self.transport.close()

    def send_400_response(self, msg: str) -> None:
        """uvicorn's answer to any request h11 cannot parse; 431 when h11 stopped buffering an
        incomplete head past ``MAX_HEAD_BYTES``."""
        buffered = len(self.conn.trailing_data[0])
        if buffered > MAX_HEAD_BYTES:
            self._refuse_head(buffered)
            return
        super().send_400_response(msg)

    def handle_websocket_upgrade(self, *request: Any) -> None:
        self._head_done()
        size = head_size(self.scope)
        if size > MAX_HEAD_BYTES:
            self._refuse_head(size)
            return
        if self.over_cap:
            self._refuse(TOO_MANY_CONNECTIONS)
            return
        if self.over_client_cap:
            self._refuse_client(CONNECTIONS)
            return
        if self.limits is not None and self.address:
            if not self.limits.upgrade(self.address, self.loop.time()):
                self._refuse_client(UPGRADE_RATE)
                return
        if shedding(self.app_state):
            self._refuse(SHEDDING)
            return
        if self.scope["path"] == STREAM_PATH:
            busy = upgrade_refusal(self.app_state, self.client)
            if busy is not None:
                self._refuse_busy(busy)
                return
        super().handle_websocket_upgrade(*request)

    async def _route(
        self, scope: Scope, receive: ASGIReceiveCallable, send: ASGISendCallable
    ) -> None:
        """The app for a request whose head is complete: ``/healthz`` first, then the cap."""
        self._head_done()
        app: ASGI3Application = self.app_behind_gate
        size = head_size(scope) if scope["type"] == "http" else 0
        if size > MAX_HEAD_BYTES:
            refused(self.app_state, HEAD_TOO_LARGE)
            await self._answer_head_too_large(size, send)
            return
        if scope["type"] == "http" and scope["method"] == "GET" and scope["path"] == HEALTHZ_PATH:
            app = answer_healthz
        elif self.over_cap:
            refused(self.app_state, TOO_MANY_CONNECTIONS)
            app = answer_busy
        elif self.over_client_cap and self.limits is not None:
            refused_client(self.app_state, CONNECTIONS)
            body = refusal_body(self.limits, self.address, CONNECTIONS)
            headers = refusal_headers(self.limits, CONNECTIONS, body)
            await send({"type": "http.response.start", "status": 503, "headers": headers})
            await send({"type": "http.response.body", "body": body})
            return
        await app(scope, receive, send)

    async def _answer_head_too_large(self, size: int, send: ASGISendCallable) -> None:
        headers, body = head_too_large(size)
        await send({"type": "http.response.start", "status": 431, "headers": headers})
        await send({"type": "http.response.body", "body": body})

    def _refuse_head(self, size: int) -> None:
        """431 and close, after reading what the client still sends (``LINGER_S``)."""
        self._head_done()
        if self.transport.is_closing():
            return
        refused(self.app_state, HEAD_TOO_LARGE)
        self.lingering = 1
        headers, body = head_too_large(size)
        self.transport.write(
            b"HTTP/1.1 431 Request Header Fields Too Large\r\n"
            + b"".join(name + b": " + value + b"\r\n" for name, value in headers)
            + b"\r\n"
            + body
        )
        self.transport.write_eof()
        self.loop.call_later(LINGER_S, self.transport.close)

    def _arm_head_timer(self) -> None:
        if self.head_timer is None:
            self.head_timer = self.loop.call_later(self.head_timeout_s, self._head_late)

    def _head_done(self) -> None:
        if self.head_timer is not None:
            self.head_timer.cancel()
            self.head_timer = None
        waiting = _over_cap.get(self.server_state)
        if waiting is not None:
            waiting.discard(self)
        if self.client_waiting and self.limits is not None:
            self.client_waiting = False
            self.limits.done_waiting(self.address)

    def _head_late(self) -> None:
        self.head_timer = None
        self._head_done()
        if not self.transport.is_closing():
            refused(self.app_state, HANDSHAKE_TIMEOUT)
            self.transport.close()

    def _refuse_client(self, reason: str) -> None:
        """HTTP 503 ``too_many_client_connections`` and close."""
        self.over_client_cap = True
        if self.limits is None or self.transport.is_closing():
            return
        refused_client(self.app_state, reason)
        self.transport.write(refusal_response(self.limits, self.address, reason))
        self.transport.close()

    def _refuse_busy(self, refusal: Refusal) -> None:
        """HTTP 503 ``server_busy`` and close (counted by ``upgrade_refusal``)."""
        self.over_cap = True
        if not self.transport.is_closing():
            self.transport.write(busy_response(refusal))
            self.transport.close()

    def _refuse(self, code: str) -> None:
        """HTTP 503 and close, whatever the client sent or will send; counted as ``code``."""
        self.over_cap = True
        if not self.transport.is_closing():
            refused(self.app_state, code)
            self.transport.write(BUSY_RESPONSE)
            self.transport.close()
