"""BoundedAcceptLoop takes at most ACCEPTS_PER_TURN connections per readiness callback and
leaves the rest in the kernel's queue; asyncio's own loop takes them all. Counted on a real
listening socket: what is still queued after the callback is what a plain accept() finds."""

from __future__ import annotations

import asyncio
import socket
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager

from lipstream.config import ServerSettings
from lipstream.server.accept_loop import ACCEPTS_PER_TURN, LOOP, BoundedAcceptLoop
from lipstream.server.runner import uvicorn_options

PENDING = 40


@contextmanager
def pending_connections(count: int) -> Iterator[socket.socket]:
    """A listening loopback socket with ``count`` connections waiting to be accepted."""
    with ExitStack() as stack:
        listener = stack.enter_context(socket.socket())
        listener.bind(("127.0.0.1", 0))
        listener.listen(2048)
        for _ in range(count):
            client = stack.enter_context(socket.socket())
            client.connect(listener.getsockname())
        listener.setblocking(False)
        yield listener


def still_queued(listener: socket.socket) -> int:
    queued = 0
    while True:
        try:
            connection, _ = listener.accept()
        except BlockingIOError:
            return queued
        connection.close()
        queued += 1


def accepted_in_one_turn(loop: asyncio.AbstractEventLoop) -> int:
    with pending_connections(PENDING) as listener:
        try:
            loop._accept_connection(asyncio.Protocol, listener, None, None, 2048)  # type: ignore[attr-defined]
            return PENDING - still_queued(listener)
        finally:
            loop.run_until_complete(asyncio.sleep(0))
            loop.close()


def test_one_turn_accepts_at_most_the_bound_and_leaves_the_rest_queued() -> None:
    assert accepted_in_one_turn(BoundedAcceptLoop()) == ACCEPTS_PER_TURN < PENDING
    assert accepted_in_one_turn(asyncio.SelectorEventLoop()) == PENDING


def test_the_server_runs_on_it() -> None:
    assert uvicorn_options(ServerSettings())["loop"] == LOOP
