"""Frames as text on a stream (stdout), for pipes: JSON lines or CSV.

Sketch: JSON lines write one object per frame, ``{"frame": 0, "time": 0.0,
"values": {"jawOpen": 0.12, ...}}``, channels in the request's order; CSV writes a
header ``frame,time,<channels>`` and a row per frame. Values are the float32s the
server sent, written with the fewest digits that read back as the same float32.
Each frame is flushed as it is written, so a reader downstream sees it on time; a
reader that goes away (a closed pipe) is counted, like a UDP receiver that is gone.
"""

from __future__ import annotations

import contextlib
import csv
import json
from collections.abc import Sequence
from typing import Literal, TextIO, TypeAlias

from ..float32 import shortest_float32
from .base import Delivery

LineFormat: TypeAlias = Literal["jsonl", "csv"]
LINE_FORMATS: tuple[LineFormat, ...] = ("jsonl", "csv")
_TIME_DIGITS = 6


class LinesSink:
    """Frames to ``stream`` as JSON lines or CSV (``line_format``)."""

    def __init__(self, stream: TextIO, line_format: LineFormat = "jsonl") -> None:
        self.stream = stream
        self.line_format = line_format
        self.names: tuple[str, ...] = ()
        self.sent = 0
        self.failed = 0
        self._csv = csv.writer(stream, lineterminator="\n")

    def open(self, channels: Sequence[str], fps: float) -> None:
        self.names = tuple(channels)
        if self.line_format == "csv":
            self._csv.writerow(["frame", "time", *self.names])
            self.stream.flush()

    def send(self, index: int, time_s: float, row: Sequence[float]) -> None:
        if self.failed:
            self.failed += 1
            return
        try:
            self._write(index, time_s, row)
        except BrokenPipeError:
            self.failed += 1
            return
        self.sent += 1

    def _write(self, index: int, time_s: float, row: Sequence[float]) -> None:
        values = [shortest_float32(value) for value in row]
        time_shown = round(time_s, _TIME_DIGITS)
        if self.line_format == "csv":
            self._csv.writerow([index, time_shown, *values])
        else:
            line = {"frame": index, "time": time_shown, "values": dict(zip(self.names, values))}
            self.stream.write(json.dumps(line, separators=(",", ":")) + "\n")
        self.stream.flush()

    def delivery(self) -> Delivery:
        return Delivery(self.sent, failed=self.failed)

    def close(self) -> None:
        with contextlib.suppress(BrokenPipeError):
            self.stream.flush()
