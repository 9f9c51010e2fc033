"""Sinks: where the bridge sends frames so that a rig that is already listening moves.

Sketch: a ``Sink`` takes a request's channels once (``open``), then one frame row at
a time (``send``). ``livelink`` packs the Live Link Face UDP packet Unreal reads,
``vmc`` the VMC protocol's OSC messages VTuber apps read, ``lines`` writes JSON lines
or CSV for pipes; ``udp`` is their transport (it counts, never raises on, a receiver
that is gone), ``target`` parses ``livelink://HOST:PORT``-style addresses and
``sound`` keeps the speech on the frames' clock. None of them needs numpy; ``vmc``
builds its OSC with python-osc.
"""

from .base import Delivery, Sink
from .errors import BridgeError
from .lines import LINE_FORMATS, LinesSink
from .livelink import LIVELINK_CURVES, LiveLinkEncoder, LiveLinkSink, encode_packet
from .sound import SoundPlayer, SpeechTrack, player_command, write_wav
from .target import LIVELINK_PORT, VMC_PORT, Target, parse_local_address, parse_target
from .udp import UdpSender

__all__ = [
    "LINE_FORMATS",
    "LIVELINK_CURVES",
    "LIVELINK_PORT",
    "VMC_PORT",
    "BridgeError",
    "Delivery",
    "LinesSink",
    "LiveLinkEncoder",
    "LiveLinkSink",
    "Sink",
    "SoundPlayer",
    "SpeechTrack",
    "Target",
    "UdpSender",
    "encode_packet",
    "parse_local_address",
    "parse_target",
    "player_command",
    "write_wav",
]
