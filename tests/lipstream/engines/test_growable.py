"""Growable keeps the rows it is given, numbered from 0, and forgets the oldest on demand."""

from __future__ import annotations

import numpy as np

from lipstream.engines.growable import Growable


def test_rows_keep_their_numbers_after_the_oldest_are_dropped() -> None:
    growable = Growable(np.float64, (2,))
    everything = np.arange(2000, dtype=np.float64).reshape(1000, 2)
    for start in range(0, 1000, 7):
        growable.extend(everything[start : start + 7])
        growable.drop_before(growable.count - 10)
    assert (growable.first, growable.count, growable.held) == (990, 1000, 10)
    np.testing.assert_array_equal(growable.view(), everything[990:])
    growable.append(np.array([-1.0, -2.0]))
    np.testing.assert_array_equal(growable.view()[-1], [-1.0, -2.0])
    assert growable.count == 1001


def test_a_buffer_left_mostly_empty_shrinks() -> None:
    growable = Growable(np.int64)
    growable.extend(np.arange(100_000))
    assert len(growable.data) >= 100_000
    growable.drop_before(99_990)
    assert len(growable.data) <= 32
    np.testing.assert_array_equal(growable.view(), np.arange(99_990, 100_000))


def test_dropping_is_clamped_to_the_rows_held() -> None:
    growable = Growable(np.int64)
    growable.extend(np.arange(5))
    growable.drop_before(3)
    growable.drop_before(1)  # already gone: nothing changes
    np.testing.assert_array_equal(growable.view(), [3, 4])
    growable.drop_before(50)
    assert (growable.first, growable.held) == (5, 0)
