"""The search: Table I as written, bounds that hold, exact DP against enumeration, and the fast
search's optimum equal to exact DP's with emotions, constraints and contamination."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lipstream.engines.expressive_dp.fast_step import Layer, fast_step
from lipstream.engines.expressive_dp.search import (
    NO_NODE,
    LayerSpec,
    SearchSpace,
    one_layer,
    search,
)
from lipstream.phonemes import PHONEME_INDEX
from tests.lipstream.engines.expressive_dp.reference import path_cost

from .edp_synthetic import PHONEMES, brute_force, loop_tc, loop_unary, random_space

SILENCE = PHONEME_INDEX["sil"]


def _problem(
    seed: int, n: int, t: int, constrain: bool, contaminate: bool
) -> tuple[SearchSpace, list[LayerSpec], np.ndarray]:
    rng = np.random.default_rng(seed)
    space = random_space(rng, n)
    excluded = np.zeros(n, dtype=bool)
    if contaminate:
        excluded[rng.choice(n, size=max(1, n // 3), replace=False)] = True
    free = np.flatnonzero(~excluded)
    layers: list[LayerSpec] = []
    for _ in range(t):
        phoneme = SILENCE if rng.random() < 0.25 else int(rng.choice(PHONEMES))
        chosen = constrain and phoneme != SILENCE and rng.random() < 0.3
        layers.append(
            LayerSpec(phoneme, int(rng.integers(0, 4)), int(rng.choice(free)) if chosen else -1)
        )
    return space, layers, excluded


def test_the_compiled_transition_cost_is_table_one() -> None:
    space, _, _ = _problem(3, 12, 1, False, False)
    rules_seen = set()
    for a in range(12):
        for b in range(12):
            expected = loop_tc(space, a, b)
            assert space.tc(a, b) == pytest.approx(expected, rel=1e-9, abs=1e-12)
            pre = int(space.nodes.pre[b])
            rules_seen.add("1" if pre == a else "4" if pre < 0 else "2/3")
    assert rules_seen == {"1", "2/3", "4"}


def test_the_bounds_hold_for_every_pair() -> None:
    for seed in range(5):
        space, _, _ = _problem(seed, 14, 1, False, False)
        for a in range(14):
            for b in range(14):
                cost = loop_tc(space, a, b)
                assert cost <= space.bounds.into[b] and cost <= space.bounds.out_of[a]


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(2, 5),
    t=st.integers(1, 3),
    constrain=st.booleans(),
    contaminate=st.booleans(),
)
def test_exact_dp_finds_the_cheapest_of_all_paths(
    seed: int, n: int, t: int, constrain: bool, contaminate: bool
) -> None:
    space, layers, excluded = _problem(seed, n, t, constrain, contaminate)
    expected, _ = brute_force(space, layers, excluded)
    found = search(space, layers, excluded, fast=False)
    assert found.cost == pytest.approx(expected, rel=1e-9)
    assert path_cost(space, layers, found.path) == pytest.approx(expected, rel=1e-9)


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(2, 40),
    t=st.integers(1, 9),
    constrain=st.booleans(),
    contaminate=st.booleans(),
)
def test_the_fast_search_has_exact_dps_optimum(
    seed: int, n: int, t: int, constrain: bool, contaminate: bool
) -> None:
    space, layers, excluded = _problem(seed, n, t, constrain, contaminate)
    exact = search(space, layers, excluded, fast=False)
    fast = search(space, layers, excluded, fast=True)
    assert fast.cost == pytest.approx(exact.cost, rel=1e-9, abs=1e-9)
    assert path_cost(space, layers, fast.path) == pytest.approx(exact.cost, rel=1e-9, abs=1e-9)
    for layer, node in zip(layers, fast.path):
        if layer.phoneme == SILENCE:
            assert node == NO_NODE
        else:
            assert node == layer.constrained if layer.constrained >= 0 else not excluded[node]
            assert np.isfinite(loop_unary(space, layer, node))


@settings(max_examples=20, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(2, 40),
    t=st.integers(1, 8),
    dims=st.sampled_from([1, 5, 10, 14]),
    coarse=st.booleans(),
)
def test_the_fast_search_has_exact_dps_optimum_in_more_dimensions_and_with_ties(
    seed: int, n: int, t: int, dims: int, coarse: bool
) -> None:
    """The fast step sums velocity gaps a few coordinates at a time (2, 4, 8, then all) and
    cuts off on the partial sums; integer frames make many costs tie exactly."""
    rng = np.random.default_rng(seed)
    space = random_space(rng, n, dims, coarse)
    layers = [LayerSpec(int(rng.choice(PHONEMES)), int(rng.integers(0, 4))) for _ in range(t)]
    excluded = np.zeros(n, dtype=bool)
    exact = search(space, layers, excluded, fast=False)
    fast = search(space, layers, excluded, fast=True)
    assert fast.cost == pytest.approx(exact.cost, rel=1e-9, abs=1e-9)
    assert path_cost(space, layers, fast.path) == pytest.approx(exact.cost, rel=1e-9, abs=1e-9)


@settings(max_examples=12, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), dims=st.sampled_from([2, 5, 10, 14]))
def test_the_fast_step_finds_every_nodes_best_predecessor(seed: int, dims: int) -> None:
    """One layer against the next: every node's φ, not only the optimal path's, equals exact
    DP's (Table I as compiled for Alg. 1), on frames near three poses where the cut-offs
    decide most pairs."""
    rng = np.random.default_rng(seed)
    n = 90
    space = random_space(rng, n, dims, tight=True)
    prev = rng.choice(n, 50, replace=False)
    prev_f = np.sort(rng.uniform(0.0, 2.0 * space.packed[3], 50))
    nodes = np.arange(n)
    expected = [min(f + space.tc(int(a), int(b)) for a, f in zip(prev, prev_f)) for b in nodes]
    scratch = np.full(n, -1)
    unary = np.zeros(n)
    for frozen in (nodes, unary):  # as the search hands layers over (one compiled kernel)
        frozen.setflags(write=False)
    order, found, back = fast_step(Layer(prev, prev_f), Layer(nodes, unary), space.joins, scratch)
    assert sorted(order.tolist()) == nodes.tolist() and (scratch == -1).all()
    assert list(found) == sorted(found)
    for node, cost, a in zip(order, found, back):
        assert cost == pytest.approx(expected[node], rel=1e-9, abs=1e-12)
        assert cost == pytest.approx(prev_f[a] + space.tc(int(prev[a]), int(node)), rel=1e-9)


def test_the_tc_by_hand_holds_in_ten_dimensions() -> None:
    rng = np.random.default_rng(4)
    space = random_space(rng, 9, dims=10)
    for a in range(9):
        for b in range(9):
            assert space.tc(a, b) == pytest.approx(loop_tc(space, a, b), rel=1e-9, abs=1e-12)


def test_a_silence_splits_the_search_into_independent_segments() -> None:
    space, layers, excluded = _problem(21, 30, 8, False, False)
    layers = [
        LayerSpec(x.phoneme if x.phoneme != SILENCE else PHONEMES[0], x.emotion) for x in layers
    ]
    pause = LayerSpec(SILENCE, 0)
    joined = [*layers[:4], pause, pause, *layers[4:]]
    for fast in (True, False):
        head = search(space, layers[:4], excluded, fast=fast, before=7)
        tail = search(space, layers[4:], excluded, fast=fast)
        found = search(space, joined, excluded, fast=fast, before=7)
        assert found.cost == pytest.approx(head.cost + tail.cost, rel=1e-12)
        assert found.path.tolist() == [*head.path.tolist(), NO_NODE, NO_NODE, *tail.path.tolist()]
        # without the pause the TC across it counts and the optimum is no cheaper
        assert search(space, layers, excluded, fast=fast, before=7).cost >= found.cost - 1e-9
    assert search(space, [pause, pause], excluded).path.tolist() == [NO_NODE, NO_NODE]


def test_a_node_fixed_before_the_first_layer_prices_its_join() -> None:
    space, layers, excluded = _problem(11, 10, 3, False, False)
    before = 4
    found = search(space, layers, excluded, before=before)
    best = min(
        (path_cost(space, layers, path, before), path)
        for path in np.ndindex(*(10,) * 3)
        if all(loop_unary(space, layer, node) < np.inf for layer, node in zip(layers, path))
    )
    assert found.cost == pytest.approx(best[0], rel=1e-9)


def test_pruning_drops_nodes_and_keeps_the_optimum() -> None:
    rng = np.random.default_rng(5)
    space = random_space(rng, 60)
    strict = np.array(space.packed)
    strict[5] = strict[6] = 1e4 * strict[3]  # wrong phonemes and emotions cost far more
    from lipstream.engines.expressive_dp.costs import NodeBounds
    from lipstream.engines.expressive_dp.search import SearchSpace

    bounds = NodeBounds.of(space.nodes, space.features, strict)
    pruned_space = SearchSpace(space.nodes, space.features, bounds, strict)
    layers = [LayerSpec(int(rng.choice(PHONEMES[:4])), int(rng.integers(0, 4))) for _ in range(8)]
    excluded = np.zeros(60, dtype=bool)
    exact = search(pruned_space, layers, excluded, fast=False)
    fast = search(pruned_space, layers, excluded, fast=True)
    assert fast.cost == pytest.approx(exact.cost, rel=1e-9)
    assert fast.candidates < exact.candidates / 4


def test_contaminating_every_node_is_refused() -> None:
    from lipstream.engines.expressive_dp.contamination import Contamination
    from lipstream.errors import InvalidRequestError

    store = Contamination(3, None)
    assert store.change([0, 1], []) == [0, 1]
    with pytest.raises(InvalidRequestError) as caught:
        store.change([2], [])
    assert caught.value.where == "mark"
    assert store.nodes() == [0, 1]


def test_the_cached_pruning_stays_exact_when_contamination_takes_its_threshold_node() -> None:
    space, layers, _ = _problem(8, 40, 6, False, False)
    layers = [LayerSpec(PHONEMES[k % 4], 0) for k in range(6)]
    clean = np.zeros(40, dtype=bool)
    search(space, layers, clean)  # fills the cache
    assert space.survivors
    for _nodes, threshold, _unary in list(space.survivors.values())[:3]:
        excluded = clean.copy()
        excluded[threshold] = True
        excluded[(threshold + 7) % 40] = True
        fast = search(space, layers, excluded)
        exact = search(space, layers, excluded, fast=False)
        assert fast.cost == pytest.approx(exact.cost, rel=1e-9)
        assert not excluded[fast.path].any()


@settings(max_examples=10, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    dims=st.sampled_from([1, 3, 5, 14]),
    coarse=st.booleans(),
    contaminate=st.booleans(),
)
def test_one_layer_after_a_fixed_node_is_the_exact_steps_argmin(
    seed: int, dims: int, coarse: bool, contaminate: bool
) -> None:
    """The causal rungs' search of one layer (``one_layer``: pruned scan, exact pricing) picks
    the node exact DP over every admitted node picks, with its TC to the last bit; integer
    frames make many costs tie, where the lowest node id wins as in the exact step."""
    rng = np.random.default_rng(seed)
    n = 40
    space = random_space(rng, n, dims, coarse)
    excluded = np.zeros(n, dtype=bool)
    if contaminate:
        excluded[rng.choice(n, size=n // 4, replace=False)] = True
    for _ in range(8):
        layer = LayerSpec(int(rng.choice(PHONEMES[:4])), int(rng.integers(0, 4)))
        before = int(rng.integers(0, n))
        node, priced, tc = one_layer(space, layer, excluded, before)
        costs = [
            loop_tc(space, before, b) + loop_unary(space, layer, b) if not excluded[b] else math.inf
            for b in range(n)
        ]
        assert costs[node] == pytest.approx(min(costs), rel=1e-9, abs=1e-12)
        assert tc == space.tc(before, node)
        assert node == int(search(space, [layer], excluded, fast=False, before=before).path[0])
        assert 1 <= priced <= n - int(excluded.sum())
