"""One WebSocket connection as its ASGI messages, with no wrapper between the app and the server.

Sketch: the endpoint speaks the ASGI WebSocket messages itself. ``accept`` takes the
``websocket.connect`` event, then sends ``websocket.accept`` with the chosen subprotocol;
``send`` makes one ``websocket.send`` event (``bytes`` or ``text`` by the payload's type);
``close`` sends ``websocket.close`` with its code and reason (before ``accept`` the ASGI
server answers the upgrade with HTTP 403); ``receive`` is the server's own callable, so a
message the client sends reaches the app in one await. Starlette's ``WebSocket`` does the
same with a state check and two wrapped ``send`` callables per message; the ASGI server
checks the same states itself (it raises ``ClientDisconnected``, an ``OSError``, for a send
on a closed socket, and ``RuntimeError`` for a message out of turn), and the connection
sends nothing after its close.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable, Mapping, MutableMapping
from typing import Any, TypeAlias

Scope: TypeAlias = MutableMapping[str, Any]
Event: TypeAlias = Mapping[str, Any]
Receive: TypeAlias = Callable[[], Awaitable[Event]]
Send: TypeAlias = Callable[[Event], Awaitable[None]]


class AsgiWebSocket:
    """The ASGI ``scope``, ``receive`` and ``send`` of one WebSocket connection."""

    __slots__ = ("scope", "receive", "_send")

    def __init__(self, scope: Scope, receive: Receive, send: Send) -> None:
        self.scope = scope
        self.receive = receive
        self._send = send

    @property
    def state(self) -> Mapping[str, Any]:
        """The lifespan state the ASGI server copies into every connection's scope."""
        state: Mapping[str, Any] = self.scope.get("state") or {}
        return state

    @property
    def subprotocols(self) -> list[str]:
        return list(self.scope.get("subprotocols") or [])

    def header(self, name: bytes) -> str | None:
        """The first value of the request header ``name`` (lower case), as Latin-1 text."""
        for key, value in self.scope.get("headers") or ():
            if key.lower() == name:
                text: str = value.decode("latin-1")
                return text
        return None

    async def accept(self, subprotocol: str | None) -> bool:
        """Take the client's ``websocket.connect`` and accept with ``subprotocol``; False (and
        nothing sent) when the client left before its connect arrived."""
        event = await self.receive()
        if event["type"] != "websocket.connect":
            return False
        await self._send({"type": "websocket.accept", "subprotocol": subprotocol})
        return True

    async def send(self, payload: bytes | str) -> None:
        if isinstance(payload, bytes):
            await self._send({"type": "websocket.send", "bytes": payload})
        else:
            await self._send({"type": "websocket.send", "text": payload})

    async def close(self, code: int, reason: str = "") -> None:
        await self._send({"type": "websocket.close", "code": code, "reason": reason})
