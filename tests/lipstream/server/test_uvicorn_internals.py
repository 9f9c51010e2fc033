"""What ``closing``, ``read_window``, ``http_flush`` and ``handshake`` take from uvicorn, named on real protocol
objects.

They subclass uvicorn's protocols, override their hooks and read their private
state. uvicorn is pinned in ``pyproject.toml`` to the series tested here; an
upgrade that renames or drops any of these fails this file.
"""

from __future__ import annotations

import asyncio
import re
import socket
import tomllib
from importlib.metadata import version
from pathlib import Path
from typing import TYPE_CHECKING, Any

import uvicorn
from packaging.requirements import Requirement
from uvicorn.protocols.websockets.websockets_sansio_impl import WebSocketsSansIOProtocol
from uvicorn.server import ServerState

if TYPE_CHECKING:
    # uvicorn types its auto protocol as a bare asyncio.Protocol; http_flush types it the same way.
    from uvicorn.protocols.http.h11_impl import H11Protocol as AutoHTTPProtocol
else:
    from uvicorn.protocols.http.auto import AutoHTTPProtocol

from lipstream.server.closing import BoundedCloseProtocol
from lipstream.server.handshake import GuardedHTTPProtocol
from lipstream.server.http_flush import BoundedFlushHTTPProtocol

PYPROJECT = Path(__file__).resolve().parents[3] / "pyproject.toml"
HTTP_HOOKS = (
    "connection_made",
    "connection_lost",
    "pause_writing",
    "on_response_complete",
    "handle_websocket_upgrade",
)
WS_HOOKS = (
    "connection_made",
    "connection_lost",
    "run_asgi",
    "send_receive_event_to_app",
    "receive",
)
SHARED_STATE = ("loop", "app_state", "client", "transport")


async def _hello(scope: dict[str, Any], receive: Any, send: Any) -> None:
    await send({"type": "http.response.start", "status": 200, "headers": []})
    await send({"type": "http.response.body", "body": b"hello"})


def _config() -> uvicorn.Config:
    config = uvicorn.Config(_hello, log_level="warning", lifespan="off")
    config.load()
    return config


def test_the_installed_uvicorn_is_in_the_pinned_range() -> None:
    dependencies = tomllib.loads(PYPROJECT.read_text())["project"]["dependencies"]
    pinned = next(Requirement(d) for d in dependencies if re.match(r"uvicorn\b", d))
    assert pinned.specifier.contains(version("uvicorn"))
    assert not pinned.specifier.contains("1000.0"), "uvicorn needs an upper bound"


def test_the_hooks_overridden_are_uvicorn_s() -> None:
    for base, ours, hooks in (
        (AutoHTTPProtocol, BoundedFlushHTTPProtocol, HTTP_HOOKS),
        (AutoHTTPProtocol, GuardedHTTPProtocol, HTTP_HOOKS),
        (WebSocketsSansIOProtocol, BoundedCloseProtocol, WS_HOOKS),
    ):
        assert issubclass(ours, base)
        for hook in hooks:
            assert callable(getattr(base, hook, None)), f"{base.__name__}.{hook} is gone"


def test_the_http_protocol_state_read_by_http_flush() -> None:
    async def exchange() -> None:
        loop = asyncio.get_running_loop()
        protocol = AutoHTTPProtocol(
            config=_config(), server_state=ServerState(), app_state={"k": 1}, _loop=loop
        )
        server_end, client_end = socket.socketpair()
        await loop.connect_accepted_socket(lambda: protocol, server_end)
        for name in SHARED_STATE:
            assert hasattr(protocol, name), name
        assert protocol.loop is loop and protocol.app_state == {"k": 1}
        assert protocol.cycle is None and protocol.flow.write_paused is False
        protocol.pause_writing()
        assert protocol.flow.write_paused is True
        protocol.resume_writing()
        reader, writer = await asyncio.open_connection(sock=client_end)
        writer.write(b"GET / HTTP/1.1\r\nHost: test\r\n\r\n")
        await asyncio.wait_for(reader.readuntil(b"hello"), timeout=5.0)
        assert protocol.cycle.response_complete is True
        writer.close()
        protocol.transport.close()

    asyncio.run(exchange())


def test_the_websocket_protocol_state_read_by_closing() -> None:
    async def connect() -> None:
        loop = asyncio.get_running_loop()
        protocol = WebSocketsSansIOProtocol(
            config=_config(), server_state=ServerState(), app_state={"k": 2}, _loop=loop
        )
        server_end, client_end = socket.socketpair()
        await loop.connect_accepted_socket(lambda: protocol, server_end)
        for name in SHARED_STATE:
            assert hasattr(protocol, name), name
        assert protocol.loop is loop and protocol.app_state == {"k": 2}
        # read_window's: the message being assembled, the app's queue, the pause flag
        assert protocol.frames == [] and protocol.queue.empty() and protocol.read_paused is False
        protocol.transport.close()
        client_end.close()

    asyncio.run(connect())


async def _other(scope: dict[str, Any], receive: Any, send: Any) -> None:
    await send({"type": "http.response.start", "status": 200, "headers": []})
    await send({"type": "http.response.body", "body": b"other"})


def test_the_http_protocol_state_read_by_handshake() -> None:
    """``handshake`` counts ``connections`` (the server state's set) and puts its own
    callable in ``app``, which uvicorn reads when a request head is complete."""

    async def exchange() -> None:
        loop = asyncio.get_running_loop()
        state = ServerState()
        protocol = AutoHTTPProtocol(config=_config(), server_state=state, app_state={}, _loop=loop)
        server_end, client_end = socket.socketpair()
        await loop.connect_accepted_socket(lambda: protocol, server_end)
        assert protocol.server_state is state
        assert protocol.connections is state.connections and protocol in state.connections
        protocol.app = _other
        reader, writer = await asyncio.open_connection(sock=client_end)
        writer.write(b"GET / HTTP/1.1\r\nHost: test\r\n\r\n")
        await asyncio.wait_for(reader.readuntil(b"other"), timeout=5.0)
        writer.close()
        protocol.transport.close()

    asyncio.run(exchange())
