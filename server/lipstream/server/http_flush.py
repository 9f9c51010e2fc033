"""uvicorn's HTTP/1.1 protocol, with a bound on how long a response's unsent bytes may stand still.

Sketch: a response is written to the transport whole (``POST /v1/synthesize``
sends all frames of an utterance, megabytes, in one write) or in parts, each
part waiting while the transport's buffer is over its high-water mark.
uvicorn waits for that drain with no timeout, and when the response is done
(the keep-alive timer, ``Connection: close`` or shutdown closes the
transport) asyncio closes the socket only once the buffer is flushed: a
client that never reads its response pins the connection for good. So a
``FlushWatch`` (the policy of the WebSocket's ``closing``) looks at the
connection's unsent bytes every ``LIPSTREAM_SEND_TIMEOUT_S`` from the moment
the buffer fills or a response ends with bytes unsent, until none are left:
they must shrink, or the connection is reset. The app writes only while a
response is under way and the buffer is not full (``_responding``), and it
leaves that state when the buffer fills or the response ends, both of which
arm the watch (or when the transport closes: the response is cut short
then anyway), so the app's own writes are never blamed on the client. A
client that reads, however slowly, gets its whole response; idle keep-alive
connections have nothing unsent and are left to uvicorn's keep-alive timeout.
A WebSocket upgrade hands the connection, unsent bytes and all, to the
WebSocket protocol and its own rules (``closing``), so the watch stops there.

The base class is the one uvicorn's ``http="auto"`` picks: httptools' protocol
when ``httptools`` is installed, else h11's. Both have the hooks used here
(``pause_writing``, ``on_response_complete``, ``cycle``, ``flow``), so the
class is typed against h11's.
"""

from __future__ import annotations

from asyncio import Transport
from typing import TYPE_CHECKING, Any

from .flush_watch import FlushWatch, flush_timeout_s

if TYPE_CHECKING:
    from uvicorn.protocols.http.h11_impl import H11Protocol as AutoHTTPProtocol
else:
    from uvicorn.protocols.http.auto import AutoHTTPProtocol


class BoundedFlushHTTPProtocol(AutoHTTPProtocol):
    """An HTTP connection that is reset when its client stops taking a response."""

    def connection_made(self, transport: Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        self.flush_watch = FlushWatch(
            transport,
            self.loop,
            flush_timeout_s(self.app_state),
            "an HTTP connection",
            self.client,
            self._responding,
        )

    def connection_lost(self, exc: Exception | None) -> None:
        super().connection_lost(exc)
        self.flush_watch.stop()

    def pause_writing(self) -> None:
        super().pause_writing()
        self.flush_watch.arm()

    def on_response_complete(self) -> None:
        super().on_response_complete()
        self.flush_watch.arm()

    def handle_websocket_upgrade(self, *request: Any) -> None:
        """The WebSocket protocol takes the transport over, and with it the rules for its
        unsent bytes (h11's passes the request event, httptools' nothing)."""
        self.flush_watch.stop()
        super().handle_websocket_upgrade(*request)

    def _responding(self) -> bool:
        """Whether the app may be writing now: a response under way, room in the buffer."""
        cycle = self.cycle
        return (
            cycle is not None
            and not cycle.response_complete
            and not self.flow.write_paused
            and not self.transport.is_closing()
        )
