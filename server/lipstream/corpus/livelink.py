"""Live Link Face CSV exports (Epic's iPhone face-capture app), read as they are.

Sketch: the app writes ``Timecode`` as ``HH:MM:SS:FF.mmm`` where ``FF.mmm`` is
a fractional frame count at the take's timecode rate (60 fps), so a row's
clock is ``h*3600 + m*60 + s + FF.mmm / 60``; the frame field wraps 59 -> 00
as the seconds tick, which that sum absorbs, and a wrap past midnight adds a
day. The first row becomes t = 0. ``BlendshapeCount`` is dropped; the 52 ARKit
blendshapes and the 9 head/eye rotations (radians) are renamed from the app's
capitalization (``JawOpen``) to ARKit's (``jawOpen``) by lower-casing the
first letter.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from lipstream_client.sinks.livelink import LIVELINK_BLENDSHAPES, LIVELINK_ROTATIONS

from ..errors import CorpusError
from .frames_csv import check_increasing, require_rows
from .table import CsvTable, FrameTable, read_csv_table

TIMECODE_COLUMN = "Timecode"
COUNT_COLUMN = "BlendshapeCount"
TIMECODE_RATE = 60.0

SIDES_SWAPPED = {"jawLeft": "jawRight", "jawRight": "jawLeft"} | {
    "mouthLeft": "mouthRight",
    "mouthRight": "mouthLeft",
}
ARKIT_BLENDSHAPES: tuple[str, ...] = tuple(
    SIDES_SWAPPED.get(name, name) for name in LIVELINK_BLENDSHAPES
)
"""The 52 ARKit blendshapes in the CSV's column order: the app's UDP packet order
(``LIVELINK_BLENDSHAPES``) with the jaw's and the mouth's sides the other way round."""
ROTATIONS: tuple[str, ...] = LIVELINK_ROTATIONS
LIVELINK_CHANNELS = frozenset(ARKIT_BLENDSHAPES + ROTATIONS)

_TIMECODE = re.compile(r"^(\d{1,2}):(\d{2}):(\d{2}):(\d{1,3}(?:\.\d*)?)$")
_DAY = 86400.0


def is_livelink_header(header: tuple[str, ...]) -> bool:
    """A CSV is a Live Link Face export when its header has a ``Timecode`` column."""
    return TIMECODE_COLUMN in header


def arkit_name(app_name: str) -> str:
    """``JawOpen`` -> ``jawOpen``; ``HeadYaw`` -> ``headYaw``."""
    return app_name[:1].lower() + app_name[1:]


def read_livelink_csv(path: str | Path, *, timecode_rate: float = TIMECODE_RATE) -> FrameTable:
    """Read a Live Link Face export: times (n,) s from the first row, frames (n, c) float32,
    ARKit channel names (c,)."""
    table = read_csv_table(Path(path))
    if TIMECODE_COLUMN not in table.header:
        raise CorpusError(f"no {TIMECODE_COLUMN!r} column", where=table.where(1))
    source_columns = tuple(
        name for name in table.header if name not in (TIMECODE_COLUMN, COUNT_COLUMN)
    )
    channels = _channel_names(table, source_columns)
    require_rows(table, 2)
    times = _timecode_seconds(table, timecode_rate)
    check_increasing(table, times)
    frames = table.numeric_columns(source_columns).astype(np.float32)
    return FrameTable(times - times[0], frames, channels)


def _channel_names(table: CsvTable, source_columns: tuple[str, ...]) -> tuple[str, ...]:
    if not source_columns:
        raise CorpusError("no blendshape or rotation columns", where=table.where(1))
    channels = tuple(arkit_name(name) for name in source_columns)
    for app_name, channel in zip(source_columns, channels):
        if channel not in LIVELINK_CHANNELS:
            raise CorpusError(
                f"column {app_name!r} is neither an ARKit blendshape nor a head/eye rotation",
                where=table.where(1),
            )
    return channels


def _timecode_seconds(table: CsvTable, rate: float) -> np.ndarray:
    """Absolute seconds of each row's timecode, shape (n,), unwrapped across midnight."""
    seconds = np.empty(len(table.rows), dtype=np.float64)
    day_offset = 0.0
    for index, (text, line) in enumerate(zip(table.text_column(TIMECODE_COLUMN), table.lines)):
        value = _parse_timecode(text.strip(), rate, table.where(line)) + day_offset
        if index and value < seconds[index - 1] - _DAY / 2:
            day_offset += _DAY
            value += _DAY
        seconds[index] = value
    return seconds


def _parse_timecode(text: str, rate: float, where: str) -> float:
    match = _TIMECODE.match(text)
    if match is None:
        raise CorpusError(
            f"column {TIMECODE_COLUMN!r}: {text!r} is not a HH:MM:SS:FF.mmm timecode", where=where
        )
    hours, minutes, secs = (int(match.group(k)) for k in (1, 2, 3))
    frame = float(match.group(4))
    if hours >= 24 or minutes >= 60 or secs >= 60 or frame >= rate:
        raise CorpusError(
            f"column {TIMECODE_COLUMN!r}: {text!r} is out of range "
            f"(hours < 24, minutes and seconds < 60, frames < {rate:g})",
            where=where,
        )
    return hours * 3600.0 + minutes * 60.0 + secs + frame / rate
