"""A bound on how long a connection's unsent bytes may stand still: past it, a TCP reset.

Sketch: asyncio closes a socket only once the transport's write buffer is
flushed, and uvicorn's protocols wait for a full buffer to drain with no
timeout, so a client that never reads again pins its connection, buffers and
protocol object for good. A ``FlushWatch`` looks at the connection's unsent
bytes every ``timeout_s`` (``LIPSTREAM_SEND_TIMEOUT_S``) while there are
any: those in the transport's buffer plus, on Linux, those the kernel has
not had acknowledged (``SIOCOUTQ``). The kernel's count falls with every
read of the client's, while the transport's buffer moves only in steps of
a fraction of the kernel's buffer (about a megabyte on loopback, seconds
apart for a slow reader), so a client that reads slowly but steadily shows
progress at every check. If the count has not shrunk since the previous
check and the app wrote nothing in between, the client took nothing for a
whole ``timeout_s``: ``SO_LINGER`` 0 makes the close send a TCP RST and drop
what the kernel still holds (so no orphaned socket probes a zero window for
minutes either), and the transport is aborted. The app's writes grow the
count, so the protocol tells the watch when the app may be writing
(``writing``, checked at each check) and ``arm``s it whenever the app stops
(its buffer fills, its response ends): a check that finds the app not
writing and no ``arm`` since the previous check knows it wrote nothing in
between; after an ``arm`` it only takes a new baseline.
"""

from __future__ import annotations

import asyncio
import logging
import socket
import struct
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from .startup import server_of

if sys.platform == "linux":
    import fcntl
    import termios

logger = logging.getLogger("lipstream.server")

DEFAULT_FLUSH_TIMEOUT_S = 10.0
RESET_ON_CLOSE = struct.pack("ii", 1, 0)  # struct linger {l_onoff = 1, l_linger = 0}


def flush_timeout_s(app_state: Mapping[str, Any]) -> float:
    """``LIPSTREAM_SEND_TIMEOUT_S`` of the app whose lifespan state is ``app_state``."""
    server = server_of(app_state)
    if server is not None:
        return server.settings.send_timeout_s
    return DEFAULT_FLUSH_TIMEOUT_S


def unsent_bytes(transport: asyncio.Transport) -> int:
    """Bytes written to ``transport`` that the client has not acknowledged: the transport's
    buffer plus, on Linux, the kernel's send queue."""
    return transport.get_write_buffer_size() + _kernel_unsent(transport.get_extra_info("socket"))


def _kernel_unsent(sock: socket.socket | None) -> int:
    if sys.platform != "linux" or sock is None:
        return 0
    try:  # linux/sockios.h: SIOCOUTQ is TIOCOUTQ
        queued = fcntl.ioctl(sock.fileno(), termios.TIOCOUTQ, bytes(4))
    except (OSError, ValueError):
        return 0  # the socket is closed: the kernel holds nothing for it any more
    count: int = struct.unpack("i", queued)[0]
    return count


def reset(transport: asyncio.Transport) -> None:
    """Close with a TCP RST, dropping every unsent byte (``SO_LINGER`` 0, then abort)."""
    sock = transport.get_extra_info("socket")
    if sock is not None:
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, RESET_ON_CLOSE)
        except OSError:
            pass  # the socket is already gone: abort only frees the transport
    transport.abort()


def _never() -> bool:
    return False


@dataclass(eq=False)
class FlushWatch:
    """Resets ``transport`` when its unsent bytes stay put for ``timeout_s`` (loop time) while
    the app is not ``writing``. ``what`` and ``client`` name the connection in the log."""

    transport: asyncio.Transport
    loop: asyncio.AbstractEventLoop
    timeout_s: float
    what: str
    client: tuple[str, int] | None
    writing: Callable[[], bool] = _never
    _before: int | None = field(default=None, init=False)
    _timer: asyncio.TimerHandle | None = field(default=None, init=False)
    _over: bool = field(default=False, init=False)

    def arm(self) -> None:
        """Watch from now on while bytes are unsent; if already watching, the app may have
        written since the last check, so the next one only takes a new baseline."""
        if self._over:
            return
        if self._timer is not None:
            self._before = None
            return
        pending = unsent_bytes(self.transport)
        if pending:
            self._before = pending
            self._timer = self.loop.call_later(self.timeout_s, self._check)

    def stop(self) -> None:
        """The connection is gone: stop watching for good (its socket, and perhaps its file
        descriptor's number, now belong to no one or to another connection)."""
        self._over = True
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None

    def _check(self) -> None:
        self._timer = None
        pending = unsent_bytes(self.transport)
        if not pending:
            return
        if self.writing():
            self._before = None
        elif self._before is None or pending < self._before:
            self._before = pending
        else:
            peer = f"{self.client[0]}:{self.client[1]}" if self.client else "a client"
            logger.info(
                "%s: resetting %s whose client took none of its %d unsent bytes in %g s",
                peer,
                self.what,
                pending,
                self.timeout_s,
            )
            reset(self.transport)
            return
        self._timer = self.loop.call_later(self.timeout_s, self._check)
