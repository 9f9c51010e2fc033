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
- *shedding*: while the event loop lags far behind (``overload.OverloadPolicy.shedding``),
  a WebSocket upgrade gets the same 503 at once, with no WebSocket work;
- ``GET /healthz`` answered by a bare ASGI callable in front of the app: no routing, no
  middleware, no lifespan state, the cheapest answer the event loop can give.

Connections closed at the deadline, refused past the cap and shed are counted in
``lipstream_connections_refused`` (codes ``handshake_timeout``, ``too_many_connections`` and
``shedding``).
"""

from __future__ import annotations

import asyncio
import json
import weakref
from asyncio import Transport
from collections.abc import Mapping
from typing import Any

from uvicorn._types import ASGI3Application, ASGIReceiveCallable, ASGISendCallable, Scope
from uvicorn.server import ServerState as UvicornState

from .http_flush import BoundedFlushHTTPProtocol
from .open_files import connection_cap, open_file_limit
from .startup import server_of

HANDSHAKE_TIMEOUT = "handshake_timeout"
TOO_MANY_CONNECTIONS = "too_many_connections"
SHEDDING = "shedding"
HEALTHZ_PATH = "/healthz"
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
        self.app_behind_gate = self.app
        self.app = self._route
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
        self._arm_head_timer()

    def connection_lost(self, exc: Exception | None) -> None:
        super().connection_lost(exc)
        self._head_done()

    def on_response_complete(self) -> None:
        super().on_response_complete()
        cycle = self.cycle
        under_way = cycle is not None and not cycle.response_complete
        if not under_way and not self.transport.is_closing():
            self._arm_head_timer()

    def handle_websocket_upgrade(self, *request: Any) -> None:
        self._head_done()
        if self.over_cap:
            self._refuse(TOO_MANY_CONNECTIONS)
            return
        if shedding(self.app_state):
            self._refuse(SHEDDING)
            return
        super().handle_websocket_upgrade(*request)

    async def _route(
        self, scope: Scope, receive: ASGIReceiveCallable, send: ASGISendCallable
    ) -> None:
        """The app for a request whose head is complete: ``/healthz`` first, then the cap."""
        self._head_done()
        app: ASGI3Application = self.app_behind_gate
        if scope["type"] == "http" and scope["method"] == "GET" and scope["path"] == HEALTHZ_PATH:
            app = answer_healthz
        elif self.over_cap:
            refused(self.app_state, TOO_MANY_CONNECTIONS)
            app = answer_busy
        await app(scope, receive, send)

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

    def _head_late(self) -> None:
        self.head_timer = None
        self._head_done()
        if not self.transport.is_closing():
            refused(self.app_state, HANDSHAKE_TIMEOUT)
            self.transport.close()

    def _refuse(self, code: str) -> None:
        """HTTP 503 and close, whatever the client sent or will send; counted as ``code``."""
        self.over_cap = True
        if not self.transport.is_closing():
            refused(self.app_state, code)
            self.transport.write(BUSY_RESPONSE)
            self.transport.close()
