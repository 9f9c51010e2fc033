"""A numpy array that grows at its end, for state that streaming appends to.

Sketch: the rows live in a buffer that doubles when full, so appending n
rows one call at a time costs O(n) copies in all, and ``view()`` hands the
held rows to numpy or a compiled kernel without a copy. Rows are numbered
from 0 in the order they were appended; ``drop_before`` forgets the oldest
ones once a stream has consumed them (moving the rest to the front, and
shrinking a buffer left mostly empty), so state that is only read near its
end stays as small as that window.
"""

from __future__ import annotations

import numpy as np

_MIN_ROWS = 16


class Growable:
    """Rows of shape ``row_shape`` and ``dtype``; ``view()`` is (count - first, *row_shape):
    rows ``first`` to ``count`` - 1."""

    def __init__(self, dtype: type = np.float64, row_shape: tuple[int, ...] = ()) -> None:
        self.data: np.ndarray = np.zeros((_MIN_ROWS, *row_shape), dtype=dtype)
        self.count = 0
        self.first = 0

    @property
    def held(self) -> int:
        return self.count - self.first

    def _reserve(self, needed: int) -> None:
        if needed > len(self.data):
            grown = np.zeros(
                (max(needed, 2 * len(self.data)), *self.data.shape[1:]), dtype=self.data.dtype
            )
            grown[: self.held] = self.data[: self.held]
            self.data = grown

    def append(self, row: float | np.ndarray | tuple[float, ...]) -> None:
        held = self.count - self.first
        if held >= len(self.data):
            self._reserve(held + 1)
        self.data[held] = row
        self.count += 1

    def extend(self, rows: np.ndarray | list[float] | list[int]) -> None:
        held = self.held
        self._reserve(held + len(rows))
        self.data[held : held + len(rows)] = rows
        self.count += len(rows)

    def reserve(self, extra: int) -> np.ndarray:
        """The buffer, with room for ``extra`` rows after the held ones, for a kernel to write
        them in place; ``grow`` then counts the rows it wrote."""
        if self.count - self.first + extra > len(self.data):
            self._reserve(self.count - self.first + extra)
        return self.data

    def grow(self, rows: int) -> None:
        """Count ``rows`` more rows, written into the buffer that ``reserve`` returned."""
        self.count += rows

    def view(self) -> np.ndarray:
        return self.data[: self.count - self.first]

    def drop_before(self, index: int) -> None:
        """Forget the rows before row ``index``."""
        index = min(max(index, self.first), self.count)
        if index == self.first:
            return
        kept = self.data[index - self.first : self.held]
        if len(self.data) > 4 * max(_MIN_ROWS, len(kept)):
            rows = max(_MIN_ROWS, 2 * len(kept))
            smaller = np.zeros((rows, *self.data.shape[1:]), dtype=self.data.dtype)
            smaller[: len(kept)] = kept
            self.data = smaller
        else:
            self.data[: len(kept)] = kept.copy()
        self.first = index
