"""The WebSocket layers bench carries real frames through the server's uvicorn protocol:
each layer writes the frame ``websockets`` itself would, and takes back the payload."""

from __future__ import annotations

import asyncio

import pytest
from websockets.frames import Frame, Opcode

from lipstream.bench.websocket_layers import client_frame, measure, server_frame

LAYERS = [
    ("send", "starlette"),
    ("send", "asgi"),
    ("send", "protocol"),
    ("send", "sans-io"),
    ("receive", "starlette"),
    ("receive", "asgi"),
    ("receive", "sans-io"),
]


@pytest.mark.parametrize("size", [0, 125, 126, 4000])
def test_server_frames_are_those_of_websockets(size: int) -> None:
    payload = bytes(index % 7 for index in range(size))
    assert server_frame(payload) == Frame(Opcode.BINARY, payload).serialize(mask=False)


@pytest.mark.parametrize("size", [10, 300])
def test_client_frames_unmask_to_the_payload(size: int) -> None:
    payload = bytes(index % 13 for index in range(size))
    frame = client_frame(payload)
    header = 2 if size < 126 else 4
    mask, masked = frame[header : header + 4], frame[header + 4 :]
    assert frame[0] == 0x82 and frame[1] & 0x80
    assert bytes(byte ^ mask[index % 4] for index, byte in enumerate(masked)) == payload


@pytest.mark.parametrize("size", [160, 300])
def test_every_layer_is_checked_and_timed(size: int) -> None:
    layers = asyncio.run(measure(200, 2, size))
    assert [(row["direction"], row["layer"]) for row in layers] == LAYERS
    for row in layers:
        assert len(row["us"]) == 2 and all(value > 0 for value in row["us"])
        assert min(row["us"]) <= row["median_us"] <= max(row["us"])
