"""A numpy array that grows at its end, for state that streaming appends to.

Sketch: the rows live in a buffer that doubles when full, so appending n
rows one call at a time costs O(n) copies in all, and ``view()`` hands the
filled part to numpy or a compiled kernel without a copy.
"""

from __future__ import annotations

import numpy as np


class Growable:
    """Rows of shape ``row_shape`` and ``dtype``; ``view()`` is (count, *row_shape)."""

    def __init__(self, dtype: type = np.float64, row_shape: tuple[int, ...] = ()) -> None:
        self.data: np.ndarray = np.zeros((16, *row_shape), dtype=dtype)
        self.count = 0

    def _reserve(self, needed: int) -> None:
        if needed > len(self.data):
            grown = np.zeros(
                (max(needed, 2 * len(self.data)), *self.data.shape[1:]), dtype=self.data.dtype
            )
            grown[: self.count] = self.data[: self.count]
            self.data = grown

    def append(self, row: float | np.ndarray) -> None:
        self._reserve(self.count + 1)
        self.data[self.count] = row
        self.count += 1

    def extend(self, rows: np.ndarray | list[float] | list[int]) -> None:
        needed = self.count + len(rows)
        self._reserve(needed)
        self.data[self.count : needed] = rows
        self.count = needed

    def view(self) -> np.ndarray:
        return self.data[: self.count]
