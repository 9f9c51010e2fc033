"""The bounded queue of messages a connection reads while its work runs."""

from __future__ import annotations

from lipstream.server.read_ahead import ReadAhead, Received
from lipstream_client import Cancel, Start


def text(size: int) -> dict[str, object]:
    return {"type": "websocket.receive", "text": "x" * size}


def test_room_is_bounded_by_bytes_and_count_but_one_message_always_fits() -> None:
    queue = ReadAhead(max_bytes=100, max_messages=3)
    assert queue.has_room()
    queue.push(Received(text(500), 0.0))  # larger than the bound: still taken alone
    assert not queue.has_room() and queue.bytes == 500
    assert queue.pop() == Received(text(500), 0.0)
    assert queue.has_room() and queue.bytes == 0
    for index in range(3):
        queue.push(Received(text(10), float(index)))
    assert not queue.has_room()  # three messages
    popped = [queue.pop() for _ in range(3)]
    assert [item.at if item is not None else None for item in popped] == [0.0, 1.0, 2.0]
    assert queue.pop() is None


def test_a_waiting_start_is_found_by_its_id() -> None:
    queue = ReadAhead(max_bytes=1000)
    queue.push(Received(text(1), 0.0, Cancel("a")))
    assert not queue.starts("a")
    queue.push(Received(text(1), 0.0, Start("a", "viseme-lerp", "demo")))
    assert queue.starts("a") and not queue.starts("b")
    queue.clear()
    assert not queue.starts("a") and queue.bytes == 0
