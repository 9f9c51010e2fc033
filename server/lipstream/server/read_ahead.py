"""Client messages read ahead, in order, while a connection's work runs in the thread pool.

Sketch: a connection handles one message at a time. While a message's work
runs in the pool, the connection keeps receiving, so the WebSocket layer
keeps reading the socket and answering pings (past ``read_window``'s
window, it pauses reading until the app receives again). What it receives
waits here, with its receipt time and its decoded message, until the work
is done; then it is handled before anything newer. The queue is bounded
(``max_messages``, ``max_bytes``, at least one message): when it is full the
connection stops receiving until its work is done, which pushes back on the
client.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping
from typing import Any, NamedTuple

from lipstream_client import Phonemes, Start

from .session import InputMessage

READ_AHEAD_MESSAGES = 256
DISCONNECT: Mapping[str, Any] = {"type": "websocket.disconnect"}


class Received(NamedTuple):
    """An ASGI event received at monotonic time ``at``; ``decoded`` once it was decoded (a
    tuple: one is made for every message, and a frozen dataclass costs several times as
    much to make)."""

    event: Mapping[str, Any]
    at: float
    decoded: InputMessage | None = None

    @property
    def size(self) -> int:
        payload = self.event.get("bytes")
        if payload is None:
            payload = self.event.get("text") or ""
        return len(payload)


class ReadAhead:
    """A bounded FIFO of ``Received`` messages."""

    def __init__(self, max_bytes: int, max_messages: int = READ_AHEAD_MESSAGES) -> None:
        self.max_bytes = max_bytes
        self.max_messages = max_messages
        self.items: deque[Received] = deque()
        self.bytes = 0

    def has_room(self) -> bool:
        return not self.items or (
            len(self.items) < self.max_messages and self.bytes < self.max_bytes
        )

    def push(self, received: Received) -> None:
        self.items.append(received)
        self.bytes += received.size

    def pop(self) -> Received | None:
        if not self.items:
            return None
        received = self.items.popleft()
        self.bytes -= received.size
        return received

    def clear(self) -> None:
        self.items.clear()
        self.bytes = 0

    def phonemes(self, identifier: str) -> int:
        """How many phonemes of request ``identifier`` wait here."""
        return sum(
            len(item.decoded.items)
            for item in self.items
            if isinstance(item.decoded, Phonemes) and item.decoded.id == identifier
        )

    def starts(self, identifier: str) -> bool:
        """Whether a ``start`` of ``identifier`` waits here (a later message names that new
        request, not the one active now)."""
        return any(
            isinstance(item.decoded, Start) and item.decoded.id == identifier for item in self.items
        )
