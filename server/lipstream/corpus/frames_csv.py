"""Plain frame CSVs: a ``time`` column in seconds plus one column per channel.

Sketch: read the table strictly (see ``table``), take ``time`` as the utterance
clock (it must start at 0 and increase strictly, so it can share the clock of
the phone alignment) and every other column, in file order, as a channel.
Writing puts frame ``i`` at ``i / fps`` and prints every value with ``%.6f``.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..errors import CorpusError
from .table import CsvTable, FrameTable, read_csv_table
from .validation import MAX_PROBLEMS, raise_each

TIME_COLUMN = "time"
START_TOLERANCE = 1e-6  # seconds; the writer's %.6f resolution
VALUE_FORMAT = "%.6f"


def read_frames_csv(path: str | Path) -> FrameTable:
    """Read ``<stem>.csv``: times (n,) s, frames (n, c) float32, channel names (c,)."""
    table = read_csv_table(Path(path))
    if TIME_COLUMN not in table.header:
        raise CorpusError(
            f"no {TIME_COLUMN!r} column; the header has: {', '.join(table.header)}",
            where=table.where(1),
        )
    channels = tuple(name for name in table.header if name != TIME_COLUMN)
    if not channels:
        raise CorpusError("no channel columns besides 'time'", where=table.where(1))
    require_rows(table, 2)
    values = table.numeric_columns((TIME_COLUMN, *channels))
    times = values[:, 0]
    check_increasing(table, times)
    if abs(times[0]) > START_TOLERANCE:
        raise CorpusError(
            f"the first time is {times[0]:g} s; frame times must start at 0",
            where=table.where(table.lines[0]),
        )
    frames = values[:, 1:].astype(np.float32)
    return FrameTable(times, frames, channels)


def require_rows(table: CsvTable, minimum: int) -> None:
    if len(table.rows) < minimum:
        raise CorpusError(
            f"needs at least {minimum} data rows to define a frame rate, found {len(table.rows)}",
            where=table.path.name,
        )


def check_increasing(table: CsvTable, times: np.ndarray) -> None:
    """Name every row whose time is not after the previous row's."""
    rows = np.flatnonzero(np.diff(times) <= 0)[: MAX_PROBLEMS + 1] + 1
    raise_each(
        [
            CorpusError(
                f"time {times[row]:.9g} s is not after the previous row's {times[row - 1]:.9g} s;"
                " times must increase strictly",
                where=table.where(table.lines[row]),
            )
            for row in rows
        ],
        where=table.path.name,
    )


def write_frames_csv(
    path: str | Path, frames: np.ndarray, channels: Sequence[str], fps: float
) -> None:
    """Write frames (n, c) with frame ``i`` at ``i / fps`` s: ``time`` then the c channels."""
    text = frames_csv_text(frames, channels, fps, where=str(path))
    with open(path, "w", encoding="utf-8", newline="") as handle:
        handle.write(text)


def frames_csv_text(
    frames: np.ndarray, channels: Sequence[str], fps: float, where: str = "frames"
) -> str:
    """The CSV text of frames (n, c), frame ``i`` at ``i / fps`` s; ``where`` names the
    destination in errors."""
    frames = np.asarray(frames, dtype=np.float64)
    if frames.ndim != 2 or frames.shape[1] != len(channels):
        raise CorpusError(
            f"frames of shape {frames.shape} do not match {len(channels)} channels",
            where=where,
        )
    if TIME_COLUMN in channels:
        raise CorpusError(f"a channel may not be named {TIME_COLUMN!r}", where=where)
    header = io.StringIO()
    csv.writer(header, lineterminator="").writerow((TIME_COLUMN, *channels))
    times = np.arange(frames.shape[0], dtype=np.float64) / fps
    table = np.column_stack([times, frames])
    body = io.StringIO()
    np.savetxt(body, table, fmt=VALUE_FORMAT, delimiter=",", header=header.getvalue(), comments="")
    return body.getvalue()
