"""The WebSocket protocol pauses its socket only once a window of messages waits for the app."""

from __future__ import annotations

import asyncio
import math

import uvicorn
from uvicorn._types import ASGIReceiveEvent
from uvicorn.server import ServerState

from lipstream.server.read_window import READ_WINDOW_BYTES, ReadWindowProtocol


class _Transport:
    """Counts the protocol's pauses and resumes."""

    def __init__(self) -> None:
        self.pauses = 0
        self.resumes = 0

    def pause_reading(self) -> None:
        self.pauses += 1

    def resume_reading(self) -> None:
        self.resumes += 1


def _protocol(loop: asyncio.AbstractEventLoop) -> tuple[ReadWindowProtocol, _Transport]:
    config = uvicorn.Config(lambda *_: None, log_level="warning", lifespan="off")
    config.load()
    protocol = ReadWindowProtocol(
        config=config, server_state=ServerState(), app_state={}, _loop=loop
    )
    transport = _Transport()
    protocol.transport = transport  # type: ignore[assignment]  # a fake that counts pauses
    return protocol, transport


def _payload(message: ASGIReceiveEvent) -> bytes:
    """The bytes of a binary WebSocket message; any other event fails the test."""
    assert message["type"] == "websocket.receive"
    payload = message["bytes"]
    assert isinstance(payload, bytes)
    return payload


def _arrive(protocol: ReadWindowProtocol, payload: bytes) -> None:
    protocol.curr_msg_data_type = "bytes"
    protocol.frames = [payload[:10], payload[10:]]  # a message in two frames
    protocol.send_receive_event_to_app()


def test_reading_pauses_at_the_window_and_resumes_once_the_app_has_taken_every_message() -> None:
    async def run() -> None:
        protocol, transport = _protocol(asyncio.get_running_loop())
        size = 1000
        under_window = math.ceil(READ_WINDOW_BYTES / size) - 1
        for _ in range(under_window):
            _arrive(protocol, b"x" * size)
        assert transport.pauses == 0  # uvicorn's own protocol pauses after every message
        _arrive(protocol, b"y" * size)
        assert transport.pauses == 1 and protocol.read_paused
        _arrive(protocol, b"z" * size)  # bytes already read while the pause takes effect
        assert transport.pauses == 1
        received = [await protocol.receive() for _ in range(under_window + 2)]
        assert [len(_payload(message)) for message in received] == [size] * (under_window + 2)
        assert _payload(received[-1]) == b"z" * size
        assert transport.resumes == 1 and not protocol.read_paused
        assert protocol.queued_bytes == 0

    asyncio.run(run())


def test_a_message_larger_than_the_window_pauses_at_once_and_the_count_survives_a_disconnect() -> (
    None
):
    async def run() -> None:
        protocol, transport = _protocol(asyncio.get_running_loop())
        _arrive(protocol, b"a" * (READ_WINDOW_BYTES + 1))
        assert transport.pauses == 1
        protocol.queue.put_nowait({"type": "websocket.disconnect", "code": 1006})
        assert len(_payload(await protocol.receive())) == READ_WINDOW_BYTES + 1
        assert protocol.queued_bytes == 0
        assert (await protocol.receive())["type"] == "websocket.disconnect"
        assert protocol.queued_bytes == 0 and transport.resumes == 1

    asyncio.run(run())
