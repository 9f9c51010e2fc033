"""A Live Link Face packet decoder written from the published layout (PyLiveLinkFace's
reading of the app's packets), independent of lipstream's encoder."""

from __future__ import annotations

import struct
from typing import NamedTuple

# PyLiveLinkFace's FaceBlendShape enum (and Unreal's EARFaceBlendShape): the packet's slots.
APP_CURVES = (
    "EyeBlinkLeft EyeLookDownLeft EyeLookInLeft EyeLookOutLeft EyeLookUpLeft EyeSquintLeft "
    "EyeWideLeft EyeBlinkRight EyeLookDownRight EyeLookInRight EyeLookOutRight EyeLookUpRight "
    "EyeSquintRight EyeWideRight JawForward JawLeft JawRight JawOpen MouthClose MouthFunnel "
    "MouthPucker MouthLeft MouthRight MouthSmileLeft MouthSmileRight MouthFrownLeft "
    "MouthFrownRight MouthDimpleLeft MouthDimpleRight MouthStretchLeft MouthStretchRight "
    "MouthRollLower MouthRollUpper MouthShrugLower MouthShrugUpper MouthPressLeft "
    "MouthPressRight MouthLowerDownLeft MouthLowerDownRight MouthUpperUpLeft MouthUpperUpRight "
    "BrowDownLeft BrowDownRight BrowInnerUp BrowOuterUpLeft BrowOuterUpRight CheekPuff "
    "CheekSquintLeft CheekSquintRight NoseSneerLeft NoseSneerRight TongueOut HeadYaw HeadPitch "
    "HeadRoll LeftEyeYaw LeftEyePitch LeftEyeRoll RightEyeYaw RightEyePitch RightEyeRoll"
).split()


class Packet(NamedTuple):
    version: int
    device_id: str
    subject: str
    frame_number: int
    sub_frame: float
    fps: int
    denominator: int
    curve_count: int
    curves: tuple[float, ...]


def decode(data: bytes) -> Packet:
    """The published layout: uint32 LE version, '$' + 36-char UUID, BE int32 name length and
    name, BE int32 frame, float32 sub-frame, int32 fps and denominator, uint8 count, floats."""
    (version,) = struct.unpack_from("<I", data, 0)
    device_id = data[4:41].decode("ascii")
    (name_length,) = struct.unpack_from(">i", data, 41)
    subject = data[45 : 45 + name_length].decode("utf-8")
    at = 45 + name_length
    frame, sub_frame, fps, denominator, count = struct.unpack_from(">ifiiB", data, at)
    at += 17
    assert len(data) == at + 4 * count, "the packet ends after its curves"
    curves = struct.unpack_from(f">{count}f", data, at)
    return Packet(version, device_id, subject, frame, sub_frame, fps, denominator, count, curves)


def app_slot(channel: str) -> int:
    return APP_CURVES.index(channel[:1].upper() + channel[1:])
