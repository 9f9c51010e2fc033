"""Where the bridge sends frames, parsed from ``livelink://HOST:PORT``, ``vmc://HOST:PORT``
or ``stdout``.

Sketch: a target is a URL whose scheme names the sink. Live Link Face listens on UDP
11111 and VMC receivers (Marionettes) on UDP 39539 unless told otherwise, so the port
may be left out; an IPv6 host goes in brackets (``vmc://[::1]:39539``). ``stdout`` takes
no address. Anything else is ``invalid_target`` naming what is wrong. No I/O: resolving
the host is the UDP sender's job.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, TypeAlias
from urllib.parse import urlsplit

from .errors import INVALID_TARGET, BridgeError

TargetKind: TypeAlias = Literal["livelink", "vmc", "stdout"]
LIVELINK_PORT = 11111
"""Live Link Face's default UDP port, the one Unreal's Live Link source listens on."""
VMC_PORT = 39539
"""The VMC protocol's Marionette (receiver) port."""
DEFAULT_PORTS: dict[TargetKind, int] = {"livelink": LIVELINK_PORT, "vmc": VMC_PORT}
TARGET_FORMS = "livelink://HOST:PORT, vmc://HOST:PORT or stdout"


@dataclass(frozen=True, slots=True)
class Target:
    """A parsed target: its ``kind``, and for UDP targets ``host`` and ``port``."""

    kind: TargetKind
    host: str = ""
    port: int = 0

    def __str__(self) -> str:
        if self.kind == "stdout":
            return "stdout"
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{self.kind}://{host}:{self.port}"


def parse_target(text: str, where: str = "--to") -> Target:
    """The ``Target`` that ``text`` names; ``BridgeError`` (``invalid_target``) otherwise."""
    stripped = text.strip()
    if stripped in ("stdout", "stdout:", "stdout://", "-"):
        return Target("stdout")
    if "://" not in stripped:
        raise BridgeError(INVALID_TARGET, f"{text!r} is not one of {TARGET_FORMS}", where)
    try:
        parts = urlsplit(stripped)
        port = parts.port
    except ValueError as error:
        raise BridgeError(INVALID_TARGET, f"{text!r}: {error}", where) from None
    scheme = parts.scheme.lower()
    if scheme not in DEFAULT_PORTS:
        raise BridgeError(
            INVALID_TARGET, f"unknown target kind {parts.scheme!r}; use {TARGET_FORMS}", where
        )
    kind: TargetKind = "livelink" if scheme == "livelink" else "vmc"
    if parts.path not in ("", "/") or parts.query or parts.fragment or parts.username:
        raise BridgeError(INVALID_TARGET, f"{text!r}: a target is only HOST:PORT", where)
    host = parts.hostname or ""
    if not host:
        raise BridgeError(INVALID_TARGET, f"{text!r} names no host", where)
    if port == 0:
        raise BridgeError(INVALID_TARGET, f"{text!r}: port 0 is not a port to send to", where)
    return Target(kind, host, DEFAULT_PORTS[kind] if port is None else port)


def parse_local_address(text: str, where: str = "--bind") -> tuple[str, int]:
    """``HOST:PORT`` (``[HOST]:PORT`` for IPv6, port 0 for any) to send from."""
    try:
        parts = urlsplit(f"udp://{text.strip()}")
        port = parts.port
    except ValueError as error:
        raise BridgeError(INVALID_TARGET, f"{text!r}: {error}", where) from None
    if parts.hostname is None or port is None or parts.path:
        raise BridgeError(INVALID_TARGET, f"{text!r} is not HOST:PORT", where)
    return parts.hostname, port
