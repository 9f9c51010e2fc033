"""A kernel called through ``DirectCall`` gives the dispatcher's answers, and refuses other
argument types than its first call's while the suite checks types."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import pytest
from numba import njit

from lipstream.numerics.direct_call import DirectCall


class Pair(NamedTuple):
    weights: np.ndarray
    values: np.ndarray


@njit(cache=False)
def weighted_sum(pair: Pair, scale: float, into: np.ndarray) -> float:
    total = 0.0
    for i in range(pair.weights.shape[0]):
        into[i] = pair.weights[i] * pair.values[i]
        total += into[i]
    return total * scale


def test_direct_calls_compute_what_the_kernel_computes() -> None:
    call = DirectCall(weighted_sum)
    rng = np.random.default_rng(4)
    for _ in range(3):  # the first call binds, the others go to the entry point
        pair = Pair(rng.random(5), rng.random(5))
        into = np.zeros(5)
        got = call(pair, 2.0, into)
        assert got == pytest.approx(2.0 * float(np.dot(pair.weights, pair.values)), rel=1e-12)
        np.testing.assert_allclose(into, pair.weights * pair.values, rtol=1e-15)


def test_a_group_of_other_dtypes_is_refused_while_types_are_checked() -> None:
    call = DirectCall(weighted_sum)
    call(Pair(np.ones(3), np.ones(3)), 1.0, np.zeros(3))
    with pytest.raises(TypeError, match="weighted_sum was bound to"):
        call(Pair(np.ones(3, np.float32), np.ones(3)), 1.0, np.zeros(3))
