"""Brand's error measure (Eq. 7) as ``lipstream.bench.hmm`` takes it."""

from __future__ import annotations

import numpy as np
import pytest

from lipstream.bench.hmm import brand_error


def test_brand_error_is_the_ratio_of_squared_difference_to_squared_sum() -> None:
    mean = np.array([1.0, 1.0])
    recorded = np.array([[2.0, 1.0], [1.0, 3.0]])  # motion (1, 0), (0, 2)
    synthesized = np.array([[1.5, 1.0], [1.0, 1.0]])  # motion (0.5, 0), (0, 0)
    # |x − y|² = 0.25 + 4; |x + y|² = 2.25 + 4
    assert brand_error(recorded, synthesized, mean) == pytest.approx(4.25 / 6.25)
    assert brand_error(recorded, recorded, mean) == 0.0
    # Motion in the wrong direction is penalized: y = −x/2 gives (1.5 x)² / (0.5 x)² = 9.
    assert brand_error(recorded, mean - 0.5 * (recorded - mean), mean) == pytest.approx(9.0)
