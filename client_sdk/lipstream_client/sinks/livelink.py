"""Live Link Face packets: the UDP datagram Epic's iPhone app sends to Unreal's Live Link.

Sketch of one packet (every number big-endian but the first):

====================  =====================================================
bytes                 field
====================  =====================================================
4                     format version 6, as a little-endian uint32
37                    device id: ``$`` and a 36-character UUID, no length
4 + n                 subject name: its UTF-8 length as an int32, then it
4, 4                  frame number (int32) and sub-frame (float32)
4, 4                  frame rate: numerator and denominator (int32)
1                     curve count, 61
61 × 4                the curves (float32): ``LIVELINK_CURVES``
====================  =====================================================

This is the layout PyLiveLinkFace (JimWest/PyLiveLinkFace, written from the app's
own packets) sends. Unreal reads the same bytes as a uint8 version and a device id
after its length as an int32 (``00 00 00 24``: 0x24 is both ``$`` and 36), which is
why the id must be exactly 36 characters. The 52 ARKit curves come in the order of
Unreal's ``EARFaceBlendShape``, which is not the order of the app's CSV exports:
``jawLeft`` comes before ``jawRight`` and ``mouthLeft`` before ``mouthRight``. Then
the head's yaw, pitch and roll and each eye's, in radians.

A frame's channels are matched to curves by name: ARKit's ``jawOpen``, Live Link's
``JawOpen`` and the ``_L``/``_R`` style ``eyeBlink_L`` all land in the same slot.
Curves the frames lack are sent at rest (0), and channels Live Link has no curve for
are left out (``LiveLinkLayout.unmatched``).
"""

from __future__ import annotations

import struct
import uuid
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from datetime import datetime, timedelta
from fractions import Fraction

from .base import Delivery
from .errors import NO_LIVELINK_CHANNELS, BridgeError
from .udp import UdpSender

FORMAT_VERSION = 6
SUBJECT_MAX_BYTES = 256
_LIVELINK_BLENDSHAPES_TEXT = """
    eyeBlinkLeft eyeLookDownLeft eyeLookInLeft eyeLookOutLeft eyeLookUpLeft
    eyeSquintLeft eyeWideLeft eyeBlinkRight eyeLookDownRight eyeLookInRight
    eyeLookOutRight eyeLookUpRight eyeSquintRight eyeWideRight
    jawForward jawLeft jawRight jawOpen
    mouthClose mouthFunnel mouthPucker mouthLeft mouthRight
    mouthSmileLeft mouthSmileRight mouthFrownLeft mouthFrownRight
    mouthDimpleLeft mouthDimpleRight mouthStretchLeft mouthStretchRight
    mouthRollLower mouthRollUpper mouthShrugLower mouthShrugUpper
    mouthPressLeft mouthPressRight mouthLowerDownLeft mouthLowerDownRight
    mouthUpperUpLeft mouthUpperUpRight
    browDownLeft browDownRight browInnerUp browOuterUpLeft browOuterUpRight
    cheekPuff cheekSquintLeft cheekSquintRight noseSneerLeft noseSneerRight
    tongueOut
"""
LIVELINK_BLENDSHAPES: tuple[str, ...] = tuple(_LIVELINK_BLENDSHAPES_TEXT.split())
"""The 52 ARKit blendshapes in the packet's order (Unreal's ``EARFaceBlendShape``)."""
_LIVELINK_ROTATIONS_TEXT = """
    headYaw headPitch headRoll
    leftEyeYaw leftEyePitch leftEyeRoll
    rightEyeYaw rightEyePitch rightEyeRoll
"""
LIVELINK_ROTATIONS: tuple[str, ...] = tuple(_LIVELINK_ROTATIONS_TEXT.split())
LIVELINK_CURVES: tuple[str, ...] = LIVELINK_BLENDSHAPES + LIVELINK_ROTATIONS
"""The packet's 61 curves, in order; the app (and Unreal) spell them PascalCase."""
_CURVES = struct.Struct(f">B{len(LIVELINK_CURVES)}f")
_FRAME_TIME = struct.Struct(">ifii")
_SIDES = (("_L", "Left"), ("_R", "Right"))
_DEVICE_NAMESPACE = uuid.uuid5(uuid.NAMESPACE_URL, "https://lipstream/livelink-face")


def curve_name(channel: str) -> str:
    """The ARKit spelling of a channel named in any lipstream naming: ``JawOpen`` and
    ``jawOpen`` -> ``jawOpen``, ``eyeBlink_L`` -> ``eyeBlinkLeft``."""
    name = channel[:1].lower() + channel[1:]
    for suffix, side in _SIDES:
        if name.endswith(suffix):
            return name[: -len(suffix)] + side
    return name


def frame_rate(fps: float) -> tuple[int, int]:
    """``fps`` as the packet's (numerator, denominator): 60 -> (60, 1), 29.97 -> (2997, 100);
    NTSC's 30000/1001 is kept when ``fps`` is given to its precision."""
    ratio = Fraction(fps).limit_denominator(1001)
    return ratio.numerator, ratio.denominator


def frames_since_midnight(now: datetime, rate: tuple[int, int]) -> int:
    """The time of day of ``now`` in whole frames at ``rate`` (numerator, denominator): the
    frame number the app's timecode would give."""
    midnight = now.replace(hour=0, minute=0, second=0, microsecond=0)
    elapsed = Fraction((now - midnight) // timedelta(microseconds=1), 1_000_000)
    return int(elapsed * rate[0] / rate[1])


def device_id_for(subject: str) -> str:
    """The device id of a subject: ``$`` and a 36-character UUID derived from its name, so
    that a bridge run again for the same subject is the same device to Unreal."""
    return f"${uuid.uuid5(_DEVICE_NAMESPACE, subject)}"


def encode_packet(
    device_id: str,
    subject: str,
    frame_number: int,
    sub_frame: float,
    rate: tuple[int, int],
    curves: Sequence[float],
) -> bytes:
    """One Live Link Face datagram; ``curves`` are the 61 values of ``LIVELINK_CURVES``."""
    if len(device_id) != 37 or not device_id.startswith("$") or not device_id.isascii():
        raise ValueError(f"device id must be '$' and a 36-character UUID, got {device_id!r}")
    if len(curves) != len(LIVELINK_CURVES):
        raise ValueError(f"{len(LIVELINK_CURVES)} curves needed, got {len(curves)}")
    name = subject.encode("utf-8")
    return b"".join(
        (
            struct.pack("<I", FORMAT_VERSION),
            device_id.encode("ascii"),
            struct.pack(">i", len(name)),
            name,
            _FRAME_TIME.pack(frame_number, sub_frame, *rate),
            _CURVES.pack(len(LIVELINK_CURVES), *curves),
        )
    )


@dataclass(frozen=True, slots=True)
class LiveLinkLayout:
    """Where each frame column goes: ``slots[i]`` is the curve index of column
    ``columns[i]``; ``unmatched`` names the channels with no Live Link curve."""

    columns: tuple[int, ...]
    slots: tuple[int, ...]
    unmatched: tuple[str, ...]

    @classmethod
    def for_channels(cls, channels: Sequence[str]) -> LiveLinkLayout:
        index = {name: slot for slot, name in enumerate(LIVELINK_CURVES)}
        columns: list[int] = []
        slots: list[int] = []
        unmatched: list[str] = []
        for column, channel in enumerate(channels):
            slot = index.get(curve_name(channel))
            if slot is None or slot in slots:
                unmatched.append(channel)
            else:
                columns.append(column)
                slots.append(slot)
        if not slots:
            shown = ", ".join(channels[:6]) + (", ..." if len(channels) > 6 else "")
            raise BridgeError(
                NO_LIVELINK_CHANNELS,
                f"none of the frames' channels ({shown}) is an ARKit curve Live Link Face "
                "sends; ask for ARKit names (--preset arkit52)",
                "--preset",
            )
        return cls(tuple(columns), tuple(slots), tuple(unmatched))

    def curves(self, row: Sequence[float]) -> list[float]:
        """The 61 curve values of one frame row, at rest (0) where the row has none."""
        values = [0.0] * len(LIVELINK_CURVES)
        for column, slot in zip(self.columns, self.slots):
            values[slot] = row[column]
        return values


class LiveLinkEncoder:
    """Packets for one subject: ``packet(frame_number, row)`` after ``open(channels, fps)``.

    ``subject`` is the name Unreal lists the face under; ``device_id`` defaults to the
    subject's own (``device_id_for``)."""

    def __init__(self, subject: str = "lipstream", device_id: str | None = None) -> None:
        encoded = subject.encode("utf-8")
        if not subject.strip() or len(encoded) > SUBJECT_MAX_BYTES:
            raise BridgeError(
                "invalid_subject",
                f"a subject name is 1 to {SUBJECT_MAX_BYTES} bytes of UTF-8, got {subject!r}",
                "--subject",
            )
        self.subject = subject
        self.device_id = device_id or device_id_for(subject)
        self.layout: LiveLinkLayout | None = None
        self.rate = (60, 1)

    def open(self, channels: Sequence[str], fps: float) -> None:
        self.layout = LiveLinkLayout.for_channels(channels)
        self.rate = frame_rate(fps)

    def packet(self, frame_number: int, row: Sequence[float]) -> bytes:
        if self.layout is None:
            raise RuntimeError("open() the encoder with the frames' channels first")
        curves = self.layout.curves(row)
        return encode_packet(self.device_id, self.subject, frame_number, 0.0, self.rate, curves)


class LiveLinkSink:
    """Frames to a Live Link Face receiver (Unreal's Live Link, port 11111) over ``sender``.

    A frame's number is the request's first frame number plus its index, so the numbers
    run in order: ``first_frame_number`` when given, else the time of day in frames when
    the request opens (``wall_clock``), as the app's timecode runs."""

    def __init__(
        self,
        sender: UdpSender,
        encoder: LiveLinkEncoder,
        first_frame_number: int | None = None,
        wall_clock: Callable[[], datetime] = datetime.now,
    ) -> None:
        self.sender = sender
        self.encoder = encoder
        self.given_first_frame = first_frame_number
        self.first_frame_number = first_frame_number or 0
        self.wall_clock = wall_clock

    def open(self, channels: Sequence[str], fps: float) -> None:
        self.encoder.open(channels, fps)
        if self.given_first_frame is None:
            self.first_frame_number = frames_since_midnight(self.wall_clock(), self.encoder.rate)
        else:
            self.first_frame_number = self.given_first_frame

    def send(self, index: int, time_s: float, row: Sequence[float]) -> None:
        self.sender.send(self.encoder.packet(self.first_frame_number + index, row))

    def delivery(self) -> Delivery:
        return Delivery(self.sender.sent, self.sender.refused, self.sender.failed)

    def close(self) -> None:
        self.sender.close()
