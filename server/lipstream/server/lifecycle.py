"""Graceful shutdown: drain the WebSocket sessions, then let uvicorn exit.

Sketch: on SIGTERM uvicorn closes every WebSocket with 1012 within
milliseconds, so the app takes SIGTERM and SIGINT first. Its handlers are
installed when the lifespan starts (uvicorn's own are in place by then, in
one worker or many) and restored when it ends. The first signal starts a
drain: readiness turns 503, new connections and new ``start``s are refused
with ``shutting_down``, and each connection closes with 1001 as soon as its
requests are done. Once every connection has closed, or after
``drain_timeout_s`` (the rest are then closed with 1001 at once), the saved
uvicorn handler runs and uvicorn's own shutdown, now quick, follows. A second
SIGINT skips the wait.
"""

from __future__ import annotations

import asyncio
import logging
import signal
import threading
from collections.abc import Callable
from types import FrameType
from typing import Protocol

logger = logging.getLogger("lipstream.server")

DRAIN_SIGNALS = (signal.SIGINT, signal.SIGTERM)
ABORT_GRACE_S = 2.0


class Drainable(Protocol):
    """A connection the lifecycle can ask to finish (``drain``) or to close now (``abort``)."""

    def drain(self) -> None: ...

    def abort(self) -> None: ...


class Lifecycle:
    """The open connections of a process, the session cap, and the drain."""

    def __init__(self, max_sessions: int, on_drain: Callable[[], None] | None = None) -> None:
        """``on_drain`` runs once, when the drain begins (e.g. to publish it as a metric)."""
        self.max_sessions = max_sessions
        self.on_drain = on_drain
        self.connections: set[Drainable] = set()
        self.draining = False
        self._empty = asyncio.Event()
        self._empty.set()

    def admit(self, connection: Drainable) -> bool:
        """Register ``connection`` unless the process is at its session cap."""
        if len(self.connections) >= self.max_sessions:
            return False
        self.connections.add(connection)
        self._empty.clear()
        return True

    def release(self, connection: Drainable) -> None:
        self.connections.discard(connection)
        if not self.connections:
            self._empty.set()

    def begin_drain(self) -> None:
        """Refuse new work and ask every connection to close once its requests are done."""
        if self.draining:
            return
        self.draining = True
        if self.on_drain is not None:
            self.on_drain()
        logger.info("draining %d connection(s) for shutdown", len(self.connections))
        for connection in list(self.connections):
            connection.drain()

    async def drain(self, timeout_s: float) -> int:
        """Drain and wait; the number of connections that had to be closed at the deadline."""
        self.begin_drain()
        try:
            await asyncio.wait_for(self._empty.wait(), timeout_s)
            return 0
        except TimeoutError:
            leftover = list(self.connections)
            logger.warning(
                "drain timeout: closing %d connection(s) with requests in flight", len(leftover)
            )
            for connection in leftover:
                connection.abort()
        try:
            await asyncio.wait_for(self._empty.wait(), ABORT_GRACE_S)
        except TimeoutError:
            logger.error("%d connection(s) did not close after the drain", len(self.connections))
        return len(leftover)


SignalHandler = Callable[[int, FrameType | None], object] | int | None


def install_drain_on_signals(lifecycle: Lifecycle, timeout_s: float) -> Callable[[], None]:
    """Drain on SIGTERM/SIGINT before the previous (uvicorn's) handler runs; returns the
    function that restores the previous handlers. Does nothing outside the main thread,
    where Python cannot receive signals."""
    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    loop = asyncio.get_running_loop()
    previous: dict[int, SignalHandler] = {sig: signal.getsignal(sig) for sig in DRAIN_SIGNALS}
    tasks: set[asyncio.Task[None]] = set()

    def forward(sig: int, frame: FrameType | None) -> None:
        handler = previous[sig]
        if callable(handler):
            handler(sig, frame)
        elif handler == signal.SIG_DFL:
            signal.signal(sig, signal.SIG_DFL)
            signal.raise_signal(sig)

    async def drain_then_forward(sig: int) -> None:
        await lifecycle.drain(timeout_s)
        forward(sig, None)

    def start_drain(sig: int) -> None:
        task = loop.create_task(drain_then_forward(sig))
        tasks.add(task)
        task.add_done_callback(tasks.discard)

    received: list[int] = []

    def on_signal(sig: int, frame: FrameType | None) -> None:
        if received:
            if sig == signal.SIGINT:
                forward(sig, frame)
            return
        received.append(sig)
        loop.call_soon_threadsafe(start_drain, sig)

    for sig in DRAIN_SIGNALS:
        signal.signal(sig, on_signal)

    def restore() -> None:
        for sig, handler in previous.items():
            if signal.getsignal(sig) is on_signal:
                signal.signal(sig, handler)

    return restore
