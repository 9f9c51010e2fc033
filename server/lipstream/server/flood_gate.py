"""The accept loop's gate: a flooding address's connections refused on the bare socket.

Sketch: a connection from an address at its connection cap, with its probe lane full, gets
HTTP 503 ``too_many_client_connections`` as soon as the HTTP protocol is built, before
anything is read (``handshake``). ``ClientFloodGate`` gives that same answer a step earlier,
in the accept loop (``accept_loop.AcceptGate``), so a flood of such connections costs no
transport, protocol or task, and is counted in the same metrics.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from dataclasses import dataclass

from lipstream_client.errors import TOO_MANY_CLIENT_CONNECTIONS

from .accept_loop import BoundedAcceptLoop
from .client_limits import CONNECTIONS, refusal_response
from .handshake import CLIENT_PROBE_LANE
from .state import ServerState


@dataclass
class ClientFloodGate:
    """Refuses what ``handshake`` would refuse before reading: an address over its cap with
    ``CLIENT_PROBE_LANE`` connections already waiting."""

    server: ServerState

    def refusal(self, address: str) -> bytes | None:
        limits = self.server.clients
        if not limits.saturated(address, CLIENT_PROBE_LANE):
            return None
        metrics = self.server.metrics
        metrics.labelled(metrics.refused, TOO_MANY_CLIENT_CONNECTIONS).inc()
        metrics.labelled(metrics.client_refusals, CONNECTIONS).inc()
        return refusal_response(limits, address, CONNECTIONS)


def install_flood_gate(server: ServerState) -> Callable[[], None]:
    """Put the gate on the running loop when it is a ``BoundedAcceptLoop``; the callable
    takes it off."""
    loop = asyncio.get_running_loop()
    if not isinstance(loop, BoundedAcceptLoop):
        return lambda: None
    loop.accept_gate = ClientFloodGate(server)

    def remove() -> None:
        loop.accept_gate = None

    return remove
