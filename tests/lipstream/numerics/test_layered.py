"""The layered min-plus search against enumeration of every path."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from lipstream.numerics.layered import Trellis, first_min_plus, sliding_positions, survivors


def _trellis(seed: int, integers: bool) -> Trellis:
    """Random layers of 1 to 4 nodes, padded with costs no path may read (NaN); small
    integer costs make many paths tie exactly."""
    rng = np.random.default_rng(seed)
    sizes = rng.integers(1, 5, size=int(rng.integers(1, 6)))
    width = int(sizes.max())
    layers = len(sizes)
    if integers:
        nodes = rng.integers(0, 3, size=(layers, width)).astype(np.float64)
        edges = rng.integers(0, 3, size=(max(layers - 1, 0), width, width)).astype(np.float64)
    else:
        nodes = rng.normal(size=(layers, width))
        edges = rng.exponential(size=(max(layers - 1, 0), width, width))
    for layer, size in enumerate(sizes):
        nodes[layer, size:] = np.nan
        if layer:
            edges[layer - 1, sizes[layer - 1] :, :] = np.nan
            edges[layer - 1, :, size:] = np.nan
    return Trellis(nodes, sizes.astype(np.int64), edges)


def _cost(trellis: Trellis, path: tuple[int, ...], ending: np.ndarray | None = None) -> float:
    nodes = [trellis.nodes[layer] for layer in range(len(path))]
    if ending is not None:
        nodes[-1] = ending
    total = 0.0
    for layer, position in enumerate(path):
        if layer:
            total += trellis.edges[layer - 1, path[layer - 1], position]
        total += nodes[layer][position]
    return total


def _paths(sizes: np.ndarray) -> list[tuple[int, ...]]:
    return list(itertools.product(*(range(int(size)) for size in sizes)))


def _whole_path(trellis: Trellis) -> tuple[int, ...]:
    """Every layer's window is the whole trellis: the positions of its cheapest path."""
    layers = len(trellis.sizes)
    found = sliding_positions(
        trellis, trellis.nodes, 0, layers - 1, layers, layers, survivors(trellis)
    )
    return tuple(int(p) for p in found)


@pytest.mark.parametrize("seed", range(16))
def test_the_whole_window_is_the_enumerated_optimum(seed: int) -> None:
    trellis = _trellis(seed, integers=False)
    found = _whole_path(trellis)
    best = min(_cost(trellis, path) for path in _paths(trellis.sizes))
    assert np.isclose(_cost(trellis, found), best, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("seed", range(24))
def test_ties_go_to_the_lowest_positions_read_from_the_last_layer(seed: int) -> None:
    """Integer costs sum exactly, so every optimal path ties; the search takes the one whose
    positions, last layer first, are least."""
    trellis = _trellis(seed, integers=True)
    paths = _paths(trellis.sizes)
    best = min(_cost(trellis, path) for path in paths)
    optimal = [path for path in paths if _cost(trellis, path) == best]
    assert _whole_path(trellis) == min(optimal, key=lambda path: path[::-1])


@pytest.mark.parametrize("seed", range(16))
def test_sliding_windows_price_a_last_layer_short_of_the_end_apart(seed: int) -> None:
    rng = np.random.default_rng(100 + seed)
    trellis = _trellis(seed, integers=True)
    layers, width = trellis.nodes.shape
    endings = np.asarray(rng.integers(0, 3, size=(layers, width)), dtype=np.float64)
    low = int(rng.integers(0, layers))
    high = int(rng.integers(low, layers))
    behind, ahead = int(rng.integers(0, 4)), int(rng.integers(0, 4))
    found = sliding_positions(trellis, endings, low, high, behind, ahead, survivors(trellis))
    assert len(found) == high - low + 1
    for k in range(low, high + 1):
        first, stop = max(0, k - behind), min(k + ahead, layers - 1)
        window = Trellis(
            trellis.nodes[first : stop + 1],
            trellis.sizes[first : stop + 1],
            trellis.edges[first:stop],
        )
        ending = endings[stop] if stop == k + ahead else None
        paths = _paths(window.sizes)
        best = min(_cost(window, path, ending) for path in paths)
        optimal = [path for path in paths if _cost(window, path, ending) == best]
        assert found[k - low] == min(optimal, key=lambda path: path[::-1])[k - first]


def test_first_min_plus_takes_the_first_of_equal_sums_within_count() -> None:
    total = np.array([3.0, 1.0, 2.0, 0.0])
    column = np.array([0.0, 2.0, 1.0, -5.0])
    assert first_min_plus(total, column, 3) == (3.0, 0)
    assert first_min_plus(total, column, 4) == (-5.0, 3)
    assert first_min_plus(np.array([np.inf, np.inf]), np.zeros(2), 2) == (np.inf, 0)
