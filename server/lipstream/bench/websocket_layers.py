"""CPU per WebSocket message in each layer the ``/v1/stream`` endpoint could speak to.

Sketch: the server's own uvicorn protocol (``closing.BoundedCloseProtocol``, uvicorn's
sans-I/O WebSocket protocol with the server's read window) is opened on a transport that
keeps the bytes it is given, and an upgrade request is fed to it as bytes. Then ``messages``
binary messages of ``payload_bytes`` go through each layer, and the process's CPU time per
message is read, ``rounds`` times in turn:

- send ``starlette``: Starlette's ``WebSocket.send_bytes``, over the two ``sender`` wrappers
  its route and exception middleware put around the ASGI ``send`` (the endpoint as it is);
- send ``asgi``: the ``websocket.send`` event made by the endpoint itself, over the one
  wrapper of the exception middleware (an endpoint routed as an ASGI app);
- send ``protocol``: the ASGI server's ``send`` alone;
- send ``sans-io``: the ``websockets`` protocol and the transport's ``write``, with no ASGI
  event (an endpoint holding uvicorn's protocol itself);
- receive ``starlette``, ``asgi``: a client's masked frame fed to the protocol as bytes,
  then taken through Starlette's ``WebSocket.receive``, or the ASGI ``receive`` alone;
- receive ``sans-io``: the same bytes parsed by the ``websockets`` protocol, with no ASGI
  event and no queue.

Each send layer must write the same frame (``FIN`` and binary opcode, the length, the
payload unmasked), and each receive layer return the payload: checked before timing.
"""

from __future__ import annotations

import argparse
import asyncio
import datetime
import statistics
import time
from collections.abc import Awaitable, Callable, Sequence
from pathlib import Path
from typing import Any

from starlette._exception_handler import wrap_app_handling_exceptions
from starlette.types import Message, Receive, Scope, Send
from starlette.websockets import WebSocket, WebSocketState
from uvicorn.config import Config
from uvicorn.server import ServerState
from websockets.frames import Frame

from lipstream.results_file import machine, script_command, write_results
from lipstream.server.closing import BoundedCloseProtocol

UPGRADE = (
    b"GET /v1/stream HTTP/1.1\r\nHost: localhost\r\nUpgrade: websocket\r\n"
    b"Connection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
    b"Sec-WebSocket-Version: 13\r\n\r\n"
)
MASK = b"\x17\x2a\x5c\x81"
Case = Callable[[int], Awaitable[bytes]]


class KeptTransport(asyncio.Transport):
    """A transport that keeps the bytes written to it (the last write alone)."""

    def __init__(self) -> None:
        super().__init__()
        self.last = b""

    def write(self, data: bytes | bytearray | memoryview) -> None:
        self.last = bytes(data)

    def is_closing(self) -> bool:
        return False

    def close(self) -> None:
        return None

    def get_write_buffer_size(self) -> int:
        return 0

    def get_extra_info(self, name: str, default: Any = None) -> Any:
        peers = {"peername": ("127.0.0.1", 50000), "sockname": ("127.0.0.1", 8000)}
        return peers.get(name, default)

    def pause_reading(self) -> None:
        return None

    def resume_reading(self) -> None:
        return None


def server_frame(payload: bytes) -> bytes:
    """A final binary frame of ``payload`` as a server writes it (unmasked, under 64 KiB)."""
    if len(payload) < 126:
        return bytes([0x82, len(payload)]) + payload
    return bytes([0x82, 126]) + len(payload).to_bytes(2, "big") + payload


def client_frame(payload: bytes) -> bytes:
    """A final binary frame of ``payload`` as a client writes it (masked with ``MASK``)."""
    masked = bytes(byte ^ MASK[index % 4] for index, byte in enumerate(payload))
    if len(payload) < 126:
        return bytes([0x82, 0x80 | len(payload)]) + MASK + masked
    return bytes([0x82, 0x80 | 126]) + len(payload).to_bytes(2, "big") + MASK + masked


async def open_protocol(finished: asyncio.Event) -> BoundedCloseProtocol:
    """The server's WebSocket protocol, upgraded and accepted, on a ``KeptTransport``; its
    app returns once ``finished`` is set."""

    async def app(scope: Scope, receive: Receive, send: Send) -> None:
        await finished.wait()

    config = Config(app=app, ws="websockets-sansio", log_level="warning")
    config.ws_ping_interval = None
    config.load()
    protocol = BoundedCloseProtocol(config=config, server_state=ServerState(), app_state={})
    protocol.connection_made(KeptTransport())
    protocol.data_received(UPGRADE)
    connect = await protocol.receive()
    assert connect["type"] == "websocket.connect", connect
    await protocol.send({"type": "websocket.accept", "subprotocol": None})
    return protocol


async def _wrapped(send: Send, scope: Scope, receive: Receive) -> Send:
    """``send`` as Starlette's exception handling passes it on (one ``sender`` more)."""
    passed: list[Send] = []

    async def capture(scope: Scope, receive: Receive, sender: Send) -> None:
        passed.append(sender)

    await wrap_app_handling_exceptions(capture, WebSocket(scope, receive, send))(
        scope, receive, send
    )
    return passed[0]


async def layer_cases(protocol: BoundedCloseProtocol, payload: bytes) -> dict[str, Case]:
    """Each layer's loop of ``count`` messages, by name (``send starlette`` ...); a loop
    returns what its last send wrote, or the payload its last receive took."""
    scope: Scope = protocol.scope  # type: ignore[assignment]
    receive: Receive = protocol.receive  # type: ignore[assignment]
    protocol_send: Send = protocol.send  # type: ignore[assignment]
    middleware_send = await _wrapped(protocol_send, scope, receive)
    route_send = await _wrapped(middleware_send, scope, receive)
    starlette = WebSocket(scope, receive, route_send)
    starlette.client_state = starlette.application_state = WebSocketState.CONNECTED
    conn, writable = protocol.conn, protocol.writable
    transport: KeptTransport = protocol.transport  # type: ignore[assignment]
    incoming = client_frame(payload)

    async def send_starlette(count: int) -> bytes:
        for _ in range(count):
            await starlette.send_bytes(payload)
        return transport.last

    async def send_asgi(count: int) -> bytes:
        for _ in range(count):
            await middleware_send({"type": "websocket.send", "bytes": payload})
        return transport.last

    async def send_protocol(count: int) -> bytes:
        for _ in range(count):
            await protocol_send({"type": "websocket.send", "bytes": payload})
        return transport.last

    async def send_sans_io(count: int) -> bytes:
        for _ in range(count):
            if not writable.is_set():
                await writable.wait()
            conn.send_binary(payload)
            transport.write(b"".join(conn.data_to_send()))
        return transport.last

    async def receive_starlette(count: int) -> bytes:
        event: Message = {}
        for _ in range(count):
            protocol.data_received(incoming)
            event = await starlette.receive()
        return bytes(event["bytes"])

    async def receive_asgi(count: int) -> bytes:
        event: Message = {}
        for _ in range(count):
            protocol.data_received(incoming)
            event = await receive()
        return bytes(event["bytes"])

    async def receive_sans_io(count: int) -> bytes:
        data: bytes | bytearray | memoryview = b""
        for _ in range(count):
            conn.receive_data(incoming)
            for frame in conn.events_received():
                if isinstance(frame, Frame):
                    data = frame.data
        return bytes(data)

    return {
        "send starlette": send_starlette,
        "send asgi": send_asgi,
        "send protocol": send_protocol,
        "send sans-io": send_sans_io,
        "receive starlette": receive_starlette,
        "receive asgi": receive_asgi,
        "receive sans-io": receive_sans_io,
    }


async def measure(messages: int, rounds: int, payload_bytes: int) -> list[dict[str, Any]]:
    """Each layer's µs of CPU per message, per round, after a check of what it wrote or
    took (a RuntimeError names the layer that got it wrong)."""
    payload = bytes(index % 251 for index in range(payload_bytes))
    finished = asyncio.Event()
    protocol = await open_protocol(finished)
    cases = await layer_cases(protocol, payload)
    for name, case in cases.items():
        expected = server_frame(payload) if name.startswith("send") else payload
        if await case(1) != expected:
            raise RuntimeError(f"{name} did not carry the message as a WebSocket frame should")
    figures: dict[str, list[float]] = {name: [] for name in cases}
    for _ in range(rounds):
        for name, case in cases.items():
            began = time.process_time()
            await case(messages)
            figures[name].append(1e6 * (time.process_time() - began) / messages)
    finished.set()
    await asyncio.gather(*protocol.tasks)
    layers = []
    for name, us in figures.items():
        direction, layer = name.split(" ")
        layers.append(
            {"direction": direction, "layer": layer, "us": us, "median_us": statistics.median(us)}
        )
    return layers


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--messages", type=int, default=100_000, help="messages per round")
    parser.add_argument("--rounds", type=int, default=7, help="rounds of every layer in turn")
    parser.add_argument("--payload", type=int, default=160, help="bytes per message")
    parser.add_argument("--json", type=Path, help="write the result here")
    args = parser.parse_args(argv)
    layers = asyncio.run(measure(args.messages, args.rounds, args.payload))
    for row in layers:
        print(f"{row['direction']:8s} {row['layer']:10s} {row['median_us']:6.2f} µs per message")
    if args.json is not None:
        date = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
        command = script_command("lipstream.bench.websocket_layers", argv)
        results = {"machine": machine(), "date": date, "command": command}
        settings = {"messages": args.messages, "rounds": args.rounds, "payload": args.payload}
        write_results({**results, **settings, "layers": layers}, args.json)


if __name__ == "__main__":
    main()
