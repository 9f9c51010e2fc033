"""Mode selection: the DP finds the exhaustive optimum; E_c and E_s by hand."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from lipstream.engines.dam.selection import Costs, Layer, end_derivatives
from tests.lipstream.engines.dam.reference import best_path, context_cost, smooth_cost


def _costs(rng: np.random.Generator, n_modes: int, degree: int) -> Costs:
    coefficients = rng.normal(size=(n_modes, degree + 1, 2))
    return Costs(
        previous=rng.integers(0, 5, size=(n_modes, 6)),
        following=rng.integers(0, 5, size=(n_modes, 6)),
        emotion=rng.integers(0, 5, size=(n_modes, 4)),
        starts=end_derivatives(coefficients, 0.0),
        ends=end_derivatives(coefficients, 1.0),
        reference_duration=0.1,
        alpha=1.0,
        w_context=float(rng.uniform(0.1, 10.0)),
        w_smooth=1.0,
    )


def _exhaustive_cost(costs: Costs, layers: list[Layer], path: tuple[int, ...]) -> float:
    total = 0.0
    for index, layer in enumerate(layers):
        total += costs.w_context * float(context_cost(costs, layer)[path[index]])
        if index:
            total += costs.w_smooth * float(
                smooth_cost(costs, layers[index - 1], layer)[path[index - 1], path[index]]
            )
    return total


@pytest.mark.parametrize("seed", range(12))
def test_dp_finds_the_exhaustive_optimum(seed: int) -> None:
    rng = np.random.default_rng(seed)
    costs = _costs(rng, 12, 3)
    layers = []
    for _ in range(int(rng.integers(1, 6))):
        candidates = np.sort(rng.choice(12, size=int(rng.integers(1, 5)), replace=False))
        layers.append(
            Layer(
                candidates,
                float(rng.uniform(0.05, 0.2)),
                int(rng.integers(-1, 6)),
                int(rng.integers(-1, 6)),
                int(rng.integers(-1, 4)),
            )
        )
    found = tuple(int(p) for p in best_path(costs, layers))
    every = itertools.product(*(range(len(layer.candidates)) for layer in layers))
    best = min(every, key=lambda path: _exhaustive_cost(costs, layers, path))
    assert math.isclose(
        _exhaustive_cost(costs, layers, found), _exhaustive_cost(costs, layers, best), rel_tol=1e-12
    )


def test_context_cost_is_smoothed_negative_log_likelihood() -> None:
    previous = np.array([[3, 0], [1, 0]])
    following = np.array([[0, 2], [0, 0]])
    emotion = np.zeros((2, 4), dtype=np.int64)
    zeros = np.zeros((2, 3, 1))
    costs = Costs(previous, following, emotion, zeros, zeros, 0.1, 1.0, 1.0, 1.0)
    layer = Layer(np.array([0, 1]), 0.1, previous=0, following=1, emotion=-1)
    # previous 0: (3+1)/6 and (1+1)/6; following 1: (2+1)/4 and (0+1)/4
    expected = [-math.log(4 / 6) - math.log(3 / 4), -math.log(2 / 6) - math.log(1 / 4)]
    np.testing.assert_allclose(context_cost(costs, layer), expected)
    unseen = Layer(np.array([0, 1]), 0.1, previous=1, following=-1, emotion=-1)
    np.testing.assert_allclose(context_cost(costs, unseen), [math.log(2), math.log(2)])


def test_smooth_cost_is_the_c2_jump_at_the_join() -> None:
    # A_0(t) = t^2 ends at value 1, slope 2, curvature 2; A_1(t) = 1 starts flat at 1.
    coefficients = np.array([[[0.0], [0.0], [1.0]], [[1.0], [0.0], [0.0]]])
    zeros = np.zeros((2, 6), dtype=np.int64)
    costs = Costs(
        zeros,
        zeros,
        zeros[:, :4],
        end_derivatives(coefficients, 0.0),
        end_derivatives(coefficients, 1.0),
        0.1,
        1.0,
        1.0,
        1.0,
    )
    left = Layer(np.array([0]), 0.2, -1, -1, -1)
    right = Layer(np.array([1]), 0.1, -1, -1, -1)
    # slope 2 per local time over 0.2 s = 10/s, times 0.1 s = 1; curvature 2/0.04*0.01 = 0.5
    assert math.isclose(float(smooth_cost(costs, left, right)[0, 0]), 0.0 + 1.0 + 0.25)
