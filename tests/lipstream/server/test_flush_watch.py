"""``FlushWatch``'s rule, check by check, and the kernel's count of unacknowledged bytes.

The rule runs on a loop whose timers the test fires by hand and a transport
whose buffer the test sets, so every check sees exactly the bytes the test
chose; the kernel's count is read from a real loopback TCP connection.
"""

from __future__ import annotations

import asyncio
import socket
import struct
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any, cast

from lipstream.server.flush_watch import FlushWatch, unsent_bytes
from tests.helpers import eventually

TIMEOUT_S = 2.5


class Timer:
    def __init__(self, delay: float, callback: Callable[[], None]) -> None:
        self.delay = delay
        self.callback = callback
        self.cancelled = False
        self.fired = False

    def cancel(self) -> None:
        self.cancelled = True


class ManualLoop:
    """``call_later`` records the timer; ``fire`` runs the one pending (there is at most one)."""

    def __init__(self) -> None:
        self.timers: list[Timer] = []

    def call_later(self, delay: float, callback: Callable[[], None]) -> Timer:
        self.timers.append(Timer(delay, callback))
        return self.timers[-1]

    def pending(self) -> list[Timer]:
        return [timer for timer in self.timers if not (timer.cancelled or timer.fired)]

    def fire(self) -> None:
        [timer] = self.pending()
        timer.fired = True
        timer.callback()


class RecordingSocket:
    def __init__(self) -> None:
        self.options: list[tuple[int, int, bytes]] = []

    def setsockopt(self, level: int, option: int, value: bytes) -> None:
        self.options.append((level, option, value))

    def fileno(self) -> int:
        return -1  # never a real descriptor: the kernel's count stays 0


class BufferTransport(asyncio.Transport):
    """A transport whose write buffer holds ``buffered`` bytes."""

    def __init__(self) -> None:
        super().__init__()
        self.buffered = 0
        self.aborted = False
        self.sock = RecordingSocket()

    def get_write_buffer_size(self) -> int:
        return self.buffered

    def get_extra_info(self, name: str, default: Any = None) -> Any:
        return self.sock if name == "socket" else default

    def abort(self) -> None:
        self.aborted = True


def watch(
    writing: Callable[[], bool] = lambda: False,
) -> tuple[FlushWatch, BufferTransport, ManualLoop]:
    transport, loop = BufferTransport(), ManualLoop()
    flush_watch = FlushWatch(
        transport,
        cast(asyncio.AbstractEventLoop, loop),
        TIMEOUT_S,
        "a test connection",
        ("127.0.0.1", 5),
        writing,
    )
    return flush_watch, transport, loop


def test_a_client_that_takes_nothing_for_one_timeout_is_reset() -> None:
    flush_watch, transport, loop = watch()
    transport.buffered = 1000
    flush_watch.arm()
    assert [timer.delay for timer in loop.pending()] == [TIMEOUT_S]
    loop.fire()
    assert transport.aborted
    assert transport.sock.options == [
        (socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
    ]
    assert loop.pending() == []


def test_bytes_that_shrink_at_every_check_keep_the_connection_until_none_are_left() -> None:
    flush_watch, transport, loop = watch()
    transport.buffered = 1000
    flush_watch.arm()
    for left in (999, 500, 1):
        transport.buffered = left
        loop.fire()
        assert not transport.aborted and len(loop.pending()) == 1
    transport.buffered = 0
    loop.fire()
    assert loop.pending() == [] and not transport.aborted
    flush_watch.arm()  # nothing unsent: nothing to watch
    assert loop.pending() == []


def test_growth_while_the_app_may_write_is_not_blamed_on_the_client() -> None:
    writing = [True]
    flush_watch, transport, loop = watch(lambda: writing[0])
    transport.buffered = 1000
    flush_watch.arm()
    transport.buffered = 5000
    loop.fire()  # the app was writing: a new baseline, 5000
    writing[0] = False
    transport.buffered = 4000
    loop.fire()  # progress against 5000
    flush_watch.arm()  # the buffer drained and filled again: the app wrote meanwhile
    transport.buffered = 6000
    loop.fire()  # so 6000 is only the next baseline
    assert not transport.aborted
    loop.fire()  # and 6000 again a timeout later is the client's doing
    assert transport.aborted


def test_arming_again_keeps_the_one_timer() -> None:
    flush_watch, transport, loop = watch()
    transport.buffered = 10
    flush_watch.arm()
    flush_watch.arm()
    assert len(loop.timers) == 1


def test_a_lost_connection_is_never_watched_again() -> None:
    flush_watch, transport, loop = watch()
    transport.buffered = 1000
    flush_watch.arm()
    flush_watch.stop()
    assert loop.pending() == []
    flush_watch.arm()
    assert loop.pending() == [] and not transport.aborted


class SocketTransport(BufferTransport):
    def __init__(self, sock: socket.socket) -> None:
        super().__init__()
        self.real = sock

    def get_extra_info(self, name: str, default: Any = None) -> Any:
        return self.real if name == "socket" else default


@contextmanager
def loopback_pair(receive_buffer: int) -> Iterator[tuple[socket.socket, socket.socket]]:
    with socket.create_server(("127.0.0.1", 0)) as listener:
        reader = socket.socket()
        reader.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, receive_buffer)
        reader.connect(listener.getsockname())
        writer, _ = listener.accept()
    with reader, writer:
        yield writer, reader


def test_unsent_bytes_count_what_the_kernel_holds_unacknowledged() -> None:
    with loopback_pair(4096) as (writer, reader):
        writer.setblocking(False)
        sent = 0
        try:
            while sent < 4 << 20:
                sent += writer.send(bytes(1 << 16))
        except BlockingIOError:
            pass  # every kernel buffer on the way is full
        transport = SocketTransport(writer)
        transport.buffered = 123

        def unread() -> int:
            return len(reader.recv(1 << 20, socket.MSG_PEEK | socket.MSG_DONTWAIT))

        # What the reader's kernel holds is acknowledged; the rest is still the writer's.
        eventually(lambda: unsent_bytes(transport) == 123 + sent - unread(), "acknowledged")
        assert 0 < unread() < sent
        received = 0
        while received < sent:
            received += len(reader.recv(1 << 16))
        eventually(lambda: unsent_bytes(transport) == 123, "all acknowledged")
    assert unsent_bytes(transport) == 123  # closed: the kernel holds nothing for it
