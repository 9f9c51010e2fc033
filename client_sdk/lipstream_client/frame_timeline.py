"""A request's frames assembled by index, as a player consumes them.

Sketch: ``frames`` blocks carry rows for consecutive frame indices starting
at ``first_frame``. Blocks normally follow each other; after an
``interrupt`` the return-to-rest block starts earlier and *supersedes* rows
already received, index by index (docs/reference/protocol.md, Request rules). Such a
block rewrites the timeline from its first frame: the rows the server had
sent beyond it belonged to the speech that was cut off, and the request's
final timeline (``done.stats.frames`` long) ends with the return to rest, so
they are dropped. The timeline answers "which frame is due at time t": the
row of index ``floor(t * fps)``, or the latest row received so far when
playback has run ahead of the stream.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

from .messages import Frames


class FrameTimeline:
    """Rows of one request by frame index; each row has ``n_channels`` floats."""

    def __init__(self, fps: float, blocks: Iterable[Frames] = ()) -> None:
        if not math.isfinite(fps) or fps <= 0:
            raise ValueError(f"fps must be a positive number, got {fps!r}")
        self.fps = fps
        self._rows: list[list[float] | None] = []
        self.n_channels: int | None = None
        for block in blocks:
            self.add(block)

    def add(self, block: Frames) -> None:
        """Insert ``block``'s rows at their indices. A block that starts before the end
        (the return to rest after an interrupt) replaces everything from its first frame."""
        if block.fps != self.fps:
            raise ValueError(
                f"block of request {block.id!r} is at {block.fps} fps, "
                f"the timeline at {self.fps} fps"
            )
        if self.n_channels is not None and block.n_channels != self.n_channels:
            raise ValueError(
                f"block of request {block.id!r} has {block.n_channels} channels, "
                f"earlier blocks {self.n_channels}"
            )
        self.n_channels = block.n_channels
        if block.first_frame < len(self._rows):
            del self._rows[block.end_frame :]
        if block.end_frame > len(self._rows):
            self._rows.extend([None] * (block.end_frame - len(self._rows)))
        for offset, row in enumerate(block.rows()):
            self._rows[block.first_frame + offset] = row

    def truncate(self, n_frames: int) -> None:
        """Keep frames 0 .. n_frames - 1 (``done.stats.frames`` ends the final timeline)."""
        del self._rows[max(0, n_frames) :]

    def __len__(self) -> int:
        """One past the highest frame index received."""
        return len(self._rows)

    def row(self, index: int) -> list[float] | None:
        """The row of frame ``index``, or None if it has not been received."""
        if 0 <= index < len(self._rows):
            return self._rows[index]
        return None

    def rows(self) -> list[list[float]]:
        """All rows from frame 0, shape (len(self), n_channels); ValueError if one is missing."""
        missing = [index for index, row in enumerate(self._rows) if row is None]
        if missing:
            raise ValueError(f"frames {missing[:5]} were never received")
        return [row for row in self._rows if row is not None]

    def index_at(self, time_s: float) -> int:
        """The index of the frame shown at ``time_s`` seconds: floor(time_s * fps)."""
        return max(0, math.floor(time_s * self.fps + 1e-9))

    def at(self, time_s: float) -> tuple[int, list[float]] | None:
        """(index, row) of the frame due at ``time_s``, or of the latest received frame
        before it when the due one has not arrived; None before any frame is in."""
        due = min(self.index_at(time_s), len(self._rows) - 1)
        for index in range(due, -1, -1):
            row = self._rows[index]
            if row is not None:
                return index, row
        return None
