"""uvicorn's WebSocket protocol, with a bound on how long a finished connection holds its socket.

Sketch: when the app is done with a connection (it closed it, or gave up
closing it), uvicorn closes the transport, and asyncio closes the socket only
once the transport's write buffer is flushed. A client that never reads again
never lets it flush: the socket, its buffers and the protocol object stay
forever, and neither the app's send deadline nor the keep-alive ping (whose
timeout also only closes the transport) frees them. So once the app has
returned, a ``FlushWatch`` looks at the unsent bytes: every
``send_timeout_s`` (the app's ``LIPSTREAM_SEND_TIMEOUT_S``, from the lifespan
state) they must have shrunk, or the connection is reset. The app writes
nothing more by then, so the first check already judges the client. A client
that still reads, however slowly, receives everything and the close frame;
an empty buffer leaves the closing handshake to uvicorn.
"""

from __future__ import annotations

from asyncio import BaseTransport, Transport
from typing import cast

from .flush_watch import FlushWatch, flush_timeout_s
from .read_window import ReadWindowProtocol


class BoundedCloseProtocol(ReadWindowProtocol):
    """A WebSocket connection whose socket is freed once its unsent bytes stop moving after
    the app is done with it (and which reads ahead of the app, ``read_window``)."""

    def connection_made(self, transport: BaseTransport) -> None:
        super().connection_made(transport)
        self.flush_watch = FlushWatch(
            cast(Transport, transport),
            self.loop,
            flush_timeout_s(self.app_state),
            "a closed WebSocket",
            self.client,
        )

    def connection_lost(self, exc: Exception | None) -> None:
        super().connection_lost(exc)
        self.flush_watch.stop()

    async def run_asgi(self) -> None:
        await super().run_asgi()
        self.flush_watch.arm()
