"""The VMC protocol (OSC over UDP): a frame as a VRM BlendShapeProxy update.

Sketch: per frame the sender says it is loaded (``/VMC/Ext/OK 1``) and its relative
time (``/VMC/Ext/T``, seconds), sends one ``/VMC/Ext/Blend/Val (name, value)`` for
every channel, then ``/VMC/Ext/Blend/Apply``, after which the receiver (a VMC
"Marionette": VSeeFace, Warudo, VNyan, EVMC4U) shows them all at once. The names are
the frames' channels as the request's rig preset names them: VRM expressions (``A I U
E O``, ``aa ih ou ee oh``) or ARKit's 52 for "perfect sync" avatars. Messages are
built with python-osc and sent as OSC bundles (the protocol allows bundling), in
order, each datagram at most ``max_datagram`` bytes so that none is fragmented on an
Ethernet link; ``Apply`` closes the last one.

python-osc is the ``vmc`` extra of lipstream-client, imported when a VMC sink or
message is first made: without it the rest of the SDK works, and these raise
``BridgeError`` with code ``missing_dependency``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from .base import Delivery
from .errors import MISSING_DEPENDENCY, BridgeError
from .udp import UdpSender

if TYPE_CHECKING:
    from pythonosc.osc_message import OscMessage

OK_ADDRESS = "/VMC/Ext/OK"
TIME_ADDRESS = "/VMC/Ext/T"
VALUE_ADDRESS = "/VMC/Ext/Blend/Val"
APPLY_ADDRESS = "/VMC/Ext/Blend/Apply"
MAX_DATAGRAM = 1400
"""Bytes per datagram: under a 1500-byte Ethernet MTU with IP and UDP headers."""
_BUNDLE_HEAD = 16  # "#bundle\0" and the time tag
_ELEMENT_SIZE = 4  # each bundle element is prefixed by its length


def require_python_osc(where: str = "sinks.vmc") -> None:
    """Raise ``BridgeError`` (``missing_dependency``, at ``where``) unless python-osc can be
    imported."""
    try:
        import pythonosc  # noqa: F401
    except ImportError:
        raise BridgeError(
            MISSING_DEPENDENCY,
            "the VMC sink builds its OSC messages with python-osc, which is not installed: "
            'pip install "lipstream-client[vmc]"',
            where,
        ) from None


def _message(address: str, *args: tuple[str | int | float, str]) -> OscMessage:
    from pythonosc.osc_message_builder import OscMessageBuilder

    builder = OscMessageBuilder(address)
    for value, kind in args:
        builder.add_arg(value, kind)
    return builder.build()


def frame_messages(names: Sequence[str], time_s: float, row: Sequence[float]) -> list[OscMessage]:
    """The messages of one frame, in the order they are sent."""
    require_python_osc()
    messages = [
        _message(OK_ADDRESS, (1, "i")),
        _message(TIME_ADDRESS, (float(time_s), "f")),
    ]
    messages += [
        _message(VALUE_ADDRESS, (name, "s"), (float(value), "f")) for name, value in zip(names, row)
    ]
    messages.append(_message(APPLY_ADDRESS))
    return messages


def bundle_datagrams(
    messages: Sequence[OscMessage], max_datagram: int = MAX_DATAGRAM
) -> list[bytes]:
    """``messages`` in order, packed into as few bundles of at most ``max_datagram`` bytes as
    they fit (a message larger than that alone goes in a bundle of its own)."""
    datagrams: list[bytes] = []
    batch: list[OscMessage] = []
    size = _BUNDLE_HEAD
    for message in messages:
        needed = _ELEMENT_SIZE + message.size
        if batch and size + needed > max_datagram:
            datagrams.append(_bundle(batch))
            batch, size = [], _BUNDLE_HEAD
        batch.append(message)
        size += needed
    if batch:
        datagrams.append(_bundle(batch))
    return datagrams


def _bundle(messages: Sequence[OscMessage]) -> bytes:
    from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder

    builder = OscBundleBuilder(IMMEDIATELY)
    for message in messages:
        builder.add_content(message)
    return builder.build().dgram


class VmcSink:
    """Frames to a VMC receiver (port 39539) over ``sender``, a bundle or a few per frame."""

    def __init__(self, sender: UdpSender, max_datagram: int = MAX_DATAGRAM) -> None:
        require_python_osc()
        self.sender = sender
        self.max_datagram = max_datagram
        self.names: tuple[str, ...] = ()

    def open(self, channels: Sequence[str], fps: float) -> None:
        self.names = tuple(channels)

    def send(self, index: int, time_s: float, row: Sequence[float]) -> None:
        for datagram in bundle_datagrams(
            frame_messages(self.names, time_s, row), self.max_datagram
        ):
            self.sender.send(datagram)

    def delivery(self) -> Delivery:
        return Delivery(self.sender.sent, self.sender.refused, self.sender.failed)

    def close(self) -> None:
        self.sender.close()
