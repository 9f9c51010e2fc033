"""Live Link Face CSV, as Epic's iPhone app exports a take and Unreal's importer reads it.

Sketch: the header is the app's own: ``Timecode``, ``BlendshapeCount``, the 52
ARKit blendshapes and 9 head/eye rotations in the app's order and
capitalization (``JawOpen``). Frame i (at i / fps s) gets the timecode
``HH:MM:SS:FF.mmm`` counted from 00:00:00:00.000 at the app's 60 fps timecode
rate (``FF.mmm`` is the fractional frame, to the thousandth), the count 61
and every value with 10 decimals. Channels are matched by ARKit name (``jawOpen``
or ``JawOpen``); columns the output lacks are written as 0. The corpus reader
(``corpus.livelink``) reads the file back.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..corpus.livelink import (
    ARKIT_BLENDSHAPES,
    COUNT_COLUMN,
    LIVELINK_CHANNELS,
    ROTATIONS,
    TIMECODE_COLUMN,
    TIMECODE_RATE,
    arkit_name,
)
from ..errors import InvalidRequestError

LIVELINK_ORDER: tuple[str, ...] = ARKIT_BLENDSHAPES + ROTATIONS
_MILLIFRAMES_PER_SECOND = round(TIMECODE_RATE * 1000)
_SECONDS_PER_DAY = 86400


def livelink_csv(frames: np.ndarray, channels: Sequence[str], fps: float) -> str:
    """The Live Link Face CSV text of frames (n, len(channels)) at ``fps``."""
    columns = _columns(channels)
    table = np.zeros((len(frames), len(LIVELINK_ORDER)), dtype=np.float64)
    for source, target in columns.items():
        table[:, target] = np.asarray(frames, dtype=np.float64)[:, source]
    header = [TIMECODE_COLUMN, COUNT_COLUMN, *(app_name(name) for name in LIVELINK_ORDER)]
    lines = [",".join(header)]
    for index, row in enumerate(table):
        values = ",".join(f"{value:.10f}" for value in row)
        lines.append(f"{timecode(index / fps)},{len(LIVELINK_ORDER)},{values}")
    return "\n".join(lines) + "\n"


def app_name(name: str) -> str:
    """``jawOpen`` -> ``JawOpen``: the app's capitalization of an ARKit name."""
    return name[:1].upper() + name[1:]


def timecode(seconds: float) -> str:
    """``HH:MM:SS:FF.mmm`` of a time in seconds, at the 60 fps timecode rate."""
    milliframes = round(seconds * _MILLIFRAMES_PER_SECOND)
    frames, thousandths = divmod(milliframes, 1000)
    whole_seconds, frame = divmod(frames, round(TIMECODE_RATE))
    whole_seconds %= _SECONDS_PER_DAY
    hours, rest = divmod(whole_seconds, 3600)
    minutes, secs = divmod(rest, 60)
    return f"{hours:02d}:{minutes:02d}:{secs:02d}:{frame:02d}.{thousandths:03d}"


def _columns(channels: Sequence[str]) -> dict[int, int]:
    """Output column -> Live Link column; InvalidRequestError for a channel it has not."""
    mapping: dict[int, int] = {}
    for index, name in enumerate(channels):
        arkit = arkit_name(name)
        if arkit not in LIVELINK_CHANNELS:
            raise InvalidRequestError(
                f"channel {name!r} is neither an ARKit blendshape nor a head/eye rotation, "
                "so Live Link Face has no column for it (use ARKit or livelink naming)",
                where="channels",
            )
        mapping[index] = LIVELINK_ORDER.index(arkit)
    return mapping
