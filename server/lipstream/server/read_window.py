"""Reading a WebSocket ahead of the app up to a bound, instead of pausing the socket per message.

Sketch: uvicorn's sans-I/O WebSocket protocol pauses reading its socket after every
message it queues for the app, and resumes once the app has taken the queue empty: two
``epoll_ctl`` calls and the selector's bookkeeping per message (a fifth of the loop's
py-spy samples at 400 ``anime-graph`` causal sessions; 7% of the server's CPU measured
with and without, alternating on 300). Here the protocol keeps reading while the
messages queued for the app hold fewer than ``READ_WINDOW_BYTES``, and pauses only past
that: a client sending faster than its connection takes messages in. It resumes as
uvicorn does, once the app has taken the queue empty. What one connection holds queued
stays bounded: under ``READ_WINDOW_BYTES`` plus one message (at most ``ws_max_size``),
as uvicorn's one message was.

Each message queued for the app carries, under ``ARRIVED_AT``, the monotonic time its last
bytes reached the process: the app measures from it how long the message waited for it (the
receive lag, which a storm's queueing inflates before any timer of the app sees it).
"""

from __future__ import annotations

import time
from collections import deque
from typing import Any

from uvicorn._types import ASGIReceiveEvent
from uvicorn.protocols.websockets.websockets_sansio_impl import WebSocketsSansIOProtocol

READ_WINDOW_BYTES = 1 << 16
ARRIVED_AT = "lipstream.arrived_at"


class ReadWindowProtocol(WebSocketsSansIOProtocol):
    """uvicorn's WebSocket protocol, pausing its socket only once ``READ_WINDOW_BYTES`` of
    messages wait for the app."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.queued_sizes: deque[int] = deque()
        self.queued_arrivals: deque[float] = deque()
        self.queued_bytes = 0

    def send_receive_event_to_app(self) -> None:
        size = sum(map(len, self.frames))
        waiting = self.queue.qsize()
        paused = self.read_paused
        self.read_paused = True  # so uvicorn's pause after every message is skipped
        super().send_receive_event_to_app()
        self.read_paused = paused
        if self.queue.qsize() > waiting:
            self.queued_sizes.append(size)
            self.queued_arrivals.append(time.monotonic())
            self.queued_bytes += size
        if not paused and self.queued_bytes >= READ_WINDOW_BYTES:
            self.read_paused = True
            self.transport.pause_reading()

    async def receive(self) -> ASGIReceiveEvent:
        message = await super().receive()
        if message["type"] == "websocket.receive" and self.queued_sizes:
            self.queued_bytes -= self.queued_sizes.popleft()
            message[ARRIVED_AT] = self.queued_arrivals.popleft()  # type: ignore[literal-required]
        return message
