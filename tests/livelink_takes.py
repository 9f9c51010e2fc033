"""Live Link Face CSV exports written byte for byte the way the iPhone app writes them.

Sketch: the format is copied from the app's real exports (the two takes the
Live Link tests also read when ``LIPSTREAM_LIVELINK_DIR`` points at them):
the header below, verbatim, with ``Timecode`` first, ``BlendshapeCount`` (61)
second, then the 52 ARKit blendshapes in the app's capitalization and the 9
head and eye rotations; ``Timecode`` is ``HH:MM:SS:FF.mmm`` with ``FF.mmm`` a
fractional frame at 60 fps, and successive rows step by about 1.0016 frames
(the phone's clock), so the frame field wraps 59 -> 00 about once a second;
values have 10 decimals, blendshapes in [0, 1] (many exactly 0), rotations in
radians, some negative; lines end in ``\\n``. A ``SyntheticTake`` knows its
generating parameters (start timecode, rows, step), which the tests compare
the reader against.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

APP_HEADER = (
    "Timecode,BlendshapeCount,EyeBlinkLeft,EyeLookDownLeft,EyeLookInLeft,EyeLookOutLeft,"
    "EyeLookUpLeft,EyeSquintLeft,EyeWideLeft,EyeBlinkRight,EyeLookDownRight,EyeLookInRight,"
    "EyeLookOutRight,EyeLookUpRight,EyeSquintRight,EyeWideRight,JawForward,JawRight,JawLeft,"
    "JawOpen,MouthClose,MouthFunnel,MouthPucker,MouthRight,MouthLeft,MouthSmileLeft,"
    "MouthSmileRight,MouthFrownLeft,MouthFrownRight,MouthDimpleLeft,MouthDimpleRight,"
    "MouthStretchLeft,MouthStretchRight,MouthRollLower,MouthRollUpper,MouthShrugLower,"
    "MouthShrugUpper,MouthPressLeft,MouthPressRight,MouthLowerDownLeft,MouthLowerDownRight,"
    "MouthUpperUpLeft,MouthUpperUpRight,BrowDownLeft,BrowDownRight,BrowInnerUp,BrowOuterUpLeft,"
    "BrowOuterUpRight,CheekPuff,CheekSquintLeft,CheekSquintRight,NoseSneerLeft,NoseSneerRight,"
    "TongueOut,HeadYaw,HeadPitch,HeadRoll,LeftEyeYaw,LeftEyePitch,LeftEyeRoll,RightEyeYaw,"
    "RightEyePitch,RightEyeRoll"
)
APP_COLUMNS = tuple(APP_HEADER.split(","))
N_BLENDSHAPES = 52
N_ROTATIONS = 9
TIMECODE_FPS = 60
FRAME_STEP = 1.0016  # timecode frames per row, as in the app's exports
_DAY_S = 86400


@dataclass(frozen=True)
class SyntheticTake:
    """A take to write: its file stem, first timecode (seconds of the day), rows, seed."""

    stem: str
    start_s: float
    rows: int
    seed: int

    @property
    def span_s(self) -> float:
        """Seconds from the first row's timecode to the last's (before millisecond rounding)."""
        return (self.rows - 1) * FRAME_STEP / TIMECODE_FPS

    def clock_s(self, row: int) -> float:
        return (self.start_s + row * FRAME_STEP / TIMECODE_FPS) % _DAY_S


# One take starts like the app's take 164 (19:16:29:35.273); the other runs past midnight.
TAKES = (
    SyntheticTake("LLF_Slate_1_iPhone", 19 * 3600 + 16 * 60 + 29 + 35.273 / 60, 720, 1),
    SyntheticTake("LLF_Slate_2_iPhone", _DAY_S - 4.5, 660, 2),
)


def timecode(clock_s: float) -> str:
    """``HH:MM:SS:FF.mmm`` of a clock in seconds of the day, as the app writes it."""
    thousandths = round(clock_s * TIMECODE_FPS * 1000)  # in thousandths of a frame
    whole_seconds, frame_thousandths = divmod(thousandths, TIMECODE_FPS * 1000)
    hours, rest = divmod(whole_seconds % _DAY_S, 3600)
    minutes, seconds = divmod(rest, 60)
    frame, millis = divmod(frame_thousandths, 1000)
    return f"{hours:02d}:{minutes:02d}:{seconds:02d}:{frame:02d}.{millis:03d}"


def take_values(take: SyntheticTake) -> np.ndarray:
    """(rows, 61) float64: smooth blendshape curves in [0, 1] (clipped, so often exactly 0)
    and head and eye rotations within about ±0.3 rad."""
    rng = np.random.default_rng(take.seed)
    times = np.arange(take.rows)[:, None] / TIMECODE_FPS
    rates = rng.uniform(0.2, 3.0, (1, N_BLENDSHAPES + N_ROTATIONS))
    phases = rng.uniform(0.0, 2 * math.pi, (1, N_BLENDSHAPES + N_ROTATIONS))
    waves = np.sin(2 * math.pi * rates * times + phases)
    blendshapes = np.clip(
        rng.uniform(-0.1, 0.3, N_BLENDSHAPES) + 0.4 * waves[:, :N_BLENDSHAPES], 0, 1
    )
    rotations = 0.3 * waves[:, N_BLENDSHAPES:]
    return np.round(np.hstack([blendshapes, rotations]), 10) + 0.0  # no -0.0


def write_take(directory: Path, take: SyntheticTake) -> Path:
    """Write ``take`` as ``<stem>.csv`` in ``directory``; returns the path."""
    values = take_values(take)
    lines = [APP_HEADER]
    for row in range(take.rows):
        cells = ",".join(f"{value:.10f}" for value in values[row])
        lines.append(f"{timecode(take.clock_s(row))},{N_BLENDSHAPES + N_ROTATIONS},{cells}")
    path = directory / f"{take.stem}.csv"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path
