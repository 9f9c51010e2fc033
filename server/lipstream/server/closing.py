"""uvicorn's WebSocket protocol, with a bound on how long a finished connection holds its socket.

Sketch: when the app is done with a connection (it closed it, or gave up
closing it), uvicorn closes the transport, and asyncio closes the socket only
once the transport's write buffer is flushed. A client that never reads again
never lets it flush: the socket, its buffers and the protocol object stay
forever, and neither the app's send deadline nor the keep-alive ping (whose
timeout also only closes the transport) frees them. So once the app has
returned, this protocol watches the unsent bytes: every ``send_timeout_s``
(the app's ``LIPSTREAM_SEND_TIMEOUT_S``, from the lifespan state) they must
have shrunk, or the connection is reset: ``SO_LINGER`` 0 makes the close
send a TCP RST and drop what the kernel still holds, so no orphaned socket
probes a zero window for minutes either. A client that still reads, however
slowly, receives everything and the close frame; an empty buffer leaves the
closing handshake to uvicorn.
"""

from __future__ import annotations

import logging
import socket
import struct

from uvicorn.protocols.websockets.websockets_sansio_impl import WebSocketsSansIOProtocol

from .state import ServerState

logger = logging.getLogger("lipstream.server")

DEFAULT_FLUSH_TIMEOUT_S = 10.0
RESET_ON_CLOSE = struct.pack("ii", 1, 0)  # struct linger {l_onoff = 1, l_linger = 0}


class BoundedCloseProtocol(WebSocketsSansIOProtocol):
    """A WebSocket connection whose socket is freed once its unsent bytes stop moving after
    the app is done with it."""

    async def run_asgi(self) -> None:
        await super().run_asgi()
        self._watch_flush(self.transport.get_write_buffer_size())

    def _flush_timeout_s(self) -> float:
        server = self.app_state.get("server")
        if isinstance(server, ServerState):
            return server.settings.send_timeout_s
        return DEFAULT_FLUSH_TIMEOUT_S

    def _watch_flush(self, pending: int) -> None:
        """Check again in one flush timeout whether fewer than ``pending`` bytes are unsent."""
        if self.disconnected or pending == 0:
            return
        self.loop.call_later(self._flush_timeout_s(), self._check_flush, pending)

    def _check_flush(self, before: int) -> None:
        if self.disconnected:
            return
        pending = self.transport.get_write_buffer_size()
        if 0 < pending < before:
            self._watch_flush(pending)
        elif pending:
            logger.info("%s: resetting a closed WebSocket whose client took none of its "
                        "%d unsent bytes in %g s", _peer(self.client), pending,
                        self._flush_timeout_s())
            self._reset()

    def _reset(self) -> None:
        sock = self.transport.get_extra_info("socket")
        if sock is not None:
            try:
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, RESET_ON_CLOSE)
            except OSError:
                pass  # the socket is already gone: abort only frees the transport
        self.transport.abort()


def _peer(client: tuple[str, int] | None) -> str:
    return f"{client[0]}:{client[1]}" if client else "a client"
