"""A VMC receiver for tests: python-osc's UDP server on loopback, recording every message."""

from __future__ import annotations

import contextlib
import socket
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from pythonosc.dispatcher import Dispatcher
from pythonosc.osc_server import BlockingOSCUDPServer

RECEIVE_BUFFER_BYTES = 4 << 20


class Received:
    def __init__(self) -> None:
        self.messages: list[tuple[str, tuple[Any, ...]]] = []
        self.lock = threading.Lock()

    def record(self, address: str, *args: Any) -> None:
        with self.lock:
            self.messages.append((address, args))

    def count(self, address: str) -> int:
        with self.lock:
            return sum(1 for seen, _ in self.messages if seen == address)


@contextmanager
def vmc_receiver() -> Iterator[tuple[int, Received]]:
    """(port, received) of a receiver serving until the block ends."""
    received = Received()
    dispatcher = Dispatcher()
    dispatcher.set_default_handler(received.record)
    server = BlockingOSCUDPServer(("127.0.0.1", 0), dispatcher)
    with contextlib.suppress(OSError):  # a larger buffer where allowed: no datagram lost
        server.socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER_BYTES)
    thread = threading.Thread(target=server.serve_forever, kwargs={"poll_interval": 0.05})
    thread.start()
    try:
        yield server.server_address[1], received
    finally:
        server.shutdown()
        thread.join(timeout=10)
        server.server_close()
