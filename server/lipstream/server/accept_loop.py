"""The event loop the server runs on: asyncio's, taking a bounded number of new connections
per turn.

Sketch: when the listening socket is readable, asyncio accepts connections in a loop, up to
the listen backlog (2048) in one callback, and schedules every one's ``connection_made`` at
once; in a storm of connections the heads, upgrades and refusals of hundreds then run before
the loop turns back to the sessions it serves, one stall of hundreds of milliseconds.
``BoundedAcceptLoop`` accepts at most ``ACCEPTS_PER_TURN`` per readiness callback; the rest
wait in the kernel's queue, whose length stays the listen backlog, and the selector reports
the socket readable again on the next turn, after the sessions' own I/O. uvicorn builds the
loop from the import string ``LOOP`` (its ``loop`` setting), in every worker.
"""

from __future__ import annotations

import asyncio
import socket
from typing import Any

ACCEPTS_PER_TURN = 16
LOOP = "lipstream.server.accept_loop:BoundedAcceptLoop"


class BoundedAcceptLoop(asyncio.SelectorEventLoop):
    """asyncio's selector loop, accepting at most ``ACCEPTS_PER_TURN`` connections per turn."""

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
        super()._accept_connection(  # type: ignore[misc]
            protocol_factory,
            sock,
            sslcontext,
            server,
            min(backlog, ACCEPTS_PER_TURN),
            *args,
            **kwargs,
        )
