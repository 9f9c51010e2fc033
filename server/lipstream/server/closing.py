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

An upgrade request that ``websockets`` refuses while parsing it (a header line over its
8 KiB, too many header fields, a malformed head) gets that refusal (431, 414, or just the
end of the stream) from ``websockets``, which uvicorn never sends: it neither writes it nor
closes, and the connection, out of the head deadline's reach since the upgrade, would stay
open for good. So the refusal is written and the transport closed here, counted in
``lipstream_connections_refused`` (``head_too_large`` for a size, else ``invalid_upgrade``).

The connection's client was counted by the HTTP protocol (``client_limits``); once upgraded,
its closing is reported here.
"""

from __future__ import annotations

from asyncio import BaseTransport, Transport
from typing import cast

from websockets.exceptions import HeaderLineTooLong, RequestLineTooLong, TooManyHeaders

from .flush_watch import FlushWatch, flush_timeout_s
from .handshake import HEAD_TOO_LARGE, client_limits, refused
from .read_window import ReadWindowProtocol

INVALID_UPGRADE = "invalid_upgrade"


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

    def data_received(self, data: bytes) -> None:
        super().data_received(data)
        failure = self.conn.handshake_exc
        if failure is not None and not self.handshake_initiated and not self.close_sent:
            self.close_sent = True
            self.handshake_complete = True
            too_large = isinstance(failure, (RequestLineTooLong, HeaderLineTooLong, TooManyHeaders))
            refused(self.app_state, HEAD_TOO_LARGE if too_large else INVALID_UPGRADE)
            self.transport.write(b"".join(self.conn.data_to_send()))
            self.transport.close()

    def connection_lost(self, exc: Exception | None) -> None:
        super().connection_lost(exc)
        self.flush_watch.stop()
        # The HTTP protocol counted this connection for its client and handed it over with
        # the upgrade; its own connection_lost never runs.
        limits = client_limits(self.app_state)
        if limits is not None and self.client:
            limits.closed(self.client[0], self.loop.time())

    async def run_asgi(self) -> None:
        await super().run_asgi()
        self.flush_watch.arm()
