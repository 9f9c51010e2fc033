"""Per-client limits: open connections and WebSocket upgrades per second of one address.

Sketch: the worker-wide connection cap (``handshake``) keeps the process alive under a flood,
but one client that holds or re-opens thousands of sockets then fills it alone, and every
other client, health probes included, is refused. So each worker also counts, per peer
address, its open connections (``max_connections``: the one that finds that many already
open is over the cap) and its upgrades in a token bucket (``upgrade_rate`` per second, up to
``upgrade_burst`` at once). The accounting is sans-I/O: the HTTP protocol reports
connections opening and closing and asks before each upgrade, passing monotonic time in
seconds. An address is forgotten once it holds no connection and its bucket is full again;
entries that stopped short of that (a client gone while refused) are swept whenever the
table doubles, so it stays as large as the set of clients active lately. 0 turns a limit
off (behind a reverse proxy every client has the proxy's address).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

from lipstream_client.errors import TOO_MANY_CLIENT_CONNECTIONS
from lipstream_client.messages import JsonValue

from ..config import ServerSettings

CONNECTIONS = "connections"
UPGRADE_RATE = "upgrade_rate"
SWEEP_FROM = 1024


@dataclass
class _Client:
    open: int = 0
    tokens: float = 0.0
    stamp: float = 0.0
    waiting: int = 0  # connections over the cap that may still ask for /healthz


@dataclass
class ClientLimits:
    """Open connections and upgrade tokens of each address, against the limits."""

    max_connections: int
    upgrade_rate: float
    upgrade_burst: int
    clients: dict[str, _Client] = field(default_factory=dict)
    sweep_at: int = SWEEP_FROM

    @classmethod
    def from_settings(cls, settings: ServerSettings) -> ClientLimits:
        return cls(
            settings.max_client_connections,
            settings.client_upgrade_rate,
            settings.client_upgrade_burst,
        )

    def opened(self, address: str, now: float) -> bool:
        """Count a connection from ``address``; False when it found the address at its cap."""
        client = self._client(address, now)
        within = not self.max_connections or client.open < self.max_connections
        client.open += 1
        return within

    def closed(self, address: str, now: float) -> None:
        client = self.clients.get(address)
        if client is None:
            return
        client.open -= 1
        self._forget_if_idle(address, client, now)

    def upgrade(self, address: str, now: float) -> bool:
        """Take a token for an upgrade from ``address``; False when none is left."""
        if not self.upgrade_rate:
            return True
        client = self._client(address, now)
        self._refill(client, now)
        if client.tokens < 1.0:
            return False
        client.tokens -= 1.0
        return True

    def out_of_upgrades(self, address: str, now: float) -> bool:
        """Whether an upgrade from ``address`` at ``now`` would find no token, taking none."""
        client = self.clients.get(address)
        if not self.upgrade_rate or client is None:
            return False
        elapsed = max(0.0, now - client.stamp)
        return client.tokens + elapsed * self.upgrade_rate < 1.0

    def retry_after_s(self, reason: str) -> int:
        """Whole seconds until a refused client may try again: one token's refill for the
        rate, else a second (connections close at their own pace)."""
        if reason == UPGRADE_RATE and self.upgrade_rate:
            return max(1, math.ceil(1.0 / self.upgrade_rate))
        return 1

    def wait(self, address: str) -> int:
        """Mark one more connection of ``address`` over the cap as waiting for its head; the
        number that were waiting before it."""
        client = self.clients[address]
        client.waiting += 1
        return client.waiting - 1

    def done_waiting(self, address: str) -> None:
        client = self.clients.get(address)
        if client is not None:
            client.waiting -= 1

    def saturated(self, address: str, probe_lane: int) -> bool:
        """Whether a new connection from ``address`` would be refused at once: the address
        is at its connection cap with ``probe_lane`` of its connections already waiting."""
        client = self.clients.get(address)
        return (
            client is not None
            and bool(self.max_connections)
            and client.open >= self.max_connections
            and client.waiting >= probe_lane
        )

    def open_connections(self, address: str) -> int:
        client = self.clients.get(address)
        return 0 if client is None else client.open

    def _client(self, address: str, now: float) -> _Client:
        client = self.clients.get(address)
        if client is None:
            if len(self.clients) >= self.sweep_at:
                self._sweep(now)
            client = self.clients[address] = _Client(tokens=float(self.upgrade_burst), stamp=now)
        return client

    def _refill(self, client: _Client, now: float) -> None:
        elapsed = max(0.0, now - client.stamp)
        client.tokens = min(float(self.upgrade_burst), client.tokens + elapsed * self.upgrade_rate)
        client.stamp = now

    def _forget_if_idle(self, address: str, client: _Client, now: float) -> None:
        if client.open > 0:
            return
        self._refill(client, now)
        if not self.upgrade_rate or client.tokens >= self.upgrade_burst:
            del self.clients[address]

    def _sweep(self, now: float) -> None:
        for address, client in list(self.clients.items()):
            self._forget_if_idle(address, client, now)
        self.sweep_at = max(SWEEP_FROM, 2 * len(self.clients))


def refusal_body(limits: ClientLimits, address: str, reason: str) -> bytes:
    """The JSON error of HTTP 503 ``too_many_client_connections`` for ``address``."""
    retry_after_ms = 1000 * limits.retry_after_s(reason)
    details: dict[str, JsonValue] = {"reason": reason, "retry_after_ms": retry_after_ms}
    if reason == UPGRADE_RATE:
        what = (
            f"{address} opened WebSockets faster than {limits.upgrade_rate:g} per second "
            "(LIPSTREAM_CLIENT_UPGRADE_RATE)"
        )
        details["client_upgrade_rate"] = limits.upgrade_rate
    else:
        what = (
            f"{address} holds {limits.max_connections} open connections, the limit per "
            "client address (LIPSTREAM_MAX_CLIENT_CONNECTIONS)"
        )
        details["max_client_connections"] = limits.max_connections
    error = {
        "code": TOO_MANY_CLIENT_CONNECTIONS,
        "message": f"{what}; retry in {retry_after_ms} ms (details.retry_after_ms)",
        "details": details,
    }
    return json.dumps({"error": error}, separators=(",", ":")).encode()


def refusal_headers(limits: ClientLimits, reason: str, body: bytes) -> list[tuple[bytes, bytes]]:
    return [
        (b"content-type", b"application/json"),
        (b"content-length", str(len(body)).encode()),
        (b"retry-after", str(limits.retry_after_s(reason)).encode()),
        (b"connection", b"close"),
    ]


def refusal_response(limits: ClientLimits, address: str, reason: str) -> bytes:
    """The whole HTTP 503 ``too_many_client_connections`` answer, head and body."""
    body = refusal_body(limits, address, reason)
    head = b"".join(
        name + b": " + value + b"\r\n" for name, value in refusal_headers(limits, reason, body)
    )
    return b"HTTP/1.1 503 Service Unavailable\r\n" + head + b"\r\n" + body
