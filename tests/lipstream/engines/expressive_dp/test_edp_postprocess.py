"""Post-processing: the Eq. 16 join equals a dense least-squares fit; captured neighbours are
not smoothed; silences are straight lines between the nodes around them."""

from __future__ import annotations

import numpy as np
import pytest

from lipstream.engines.expressive_dp.nodes import NodeDatabase, warp_node
from lipstream.engines.expressive_dp.postprocess import (
    Renderer,
    _interpolated,
    _normal_bands,
    _sampled,
    smooth_join,
    warped_points,
)
from lipstream.numerics.banded import solve_spd_banded
from lipstream.phonemes import PHONEME_INDEX
from lipstream.timeline import PhonemeSpan


@pytest.mark.parametrize("count", [3, 4, 6])
def test_the_join_solve_equals_a_dense_least_squares_fit(count: int) -> None:
    rng = np.random.default_rng(count)
    fitted = rng.normal(size=(count, 4))
    weights = rng.choice([0.5, 1.0, 2.0], count)
    smoothness = 0.7
    curvature = np.zeros((count - 2, count))
    for row in range(count - 2):
        curvature[row, row : row + 3] = [1.0, -2.0, 1.0]
    system = np.vstack([np.diag(np.sqrt(weights)), np.sqrt(smoothness) * curvature])
    target = np.vstack([np.sqrt(weights)[:, None] * fitted, np.zeros((count - 2, 4))])
    expected = np.linalg.lstsq(system, target, rcond=None)[0]
    np.testing.assert_allclose(smooth_join(fitted, weights, smoothness), expected, atol=1e-10)


@pytest.mark.parametrize("count", [3, 4, 5, 6])
def test_the_join_solve_from_a_kept_factor_is_the_banded_solvers_to_the_last_bit(
    count: int,
) -> None:
    """The substitutions on a factor kept per weight pattern give what one dpbsv call (the
    general banded solver) gives, bit for bit, for every right-hand side."""
    rng = np.random.default_rng(10 + count)
    for _ in range(20):
        weights = rng.choice([0.5, 1.0, 2.0], count)
        fitted = rng.normal(size=(count, 12)) * 10.0 ** rng.integers(-3, 4)
        bands = _normal_bands(tuple(weights.tolist()), 1.0)
        expected = solve_spd_banded(bands, weights[:, None] * fitted)
        assert smooth_join(fitted, weights, 1.0).tobytes() == expected.tobytes()


def test_a_spans_warped_points_are_warp_nodes_to_the_last_bit() -> None:
    """The compiled warp of a span's grid points against ``nodes.warp_node`` on the span's
    relative times, for nodes of 2 to 9 frames and spans of every length and offset."""
    rng = np.random.default_rng(4)
    counts = rng.integers(2, 10, 40)
    offsets = np.concatenate([[0], np.cumsum(counts)])
    frames = rng.normal(size=(int(offsets[-1]), 5)) * 10.0 ** rng.integers(-2, 3)
    rate = 120.0
    for _ in range(300):
        node = int(rng.integers(40))
        start = float(rng.uniform(0.0, 3.0))
        end = start + float(rng.choice([0.004, 0.02, rng.uniform(0.03, 0.4)]))
        low, high = int(np.ceil(start * rate - 1e-9)), int(np.ceil(end * rate - 1e-9))
        low -= int(rng.integers(0, 2))  # a point just before the span clips to its start
        relative = (np.arange(low, high) / rate - start) / (end - start)
        expected = warp_node(frames[offsets[node] : offsets[node + 1]], relative)
        got = warped_points(frames, offsets, node, low, high, rate, start, end)
        assert got.shape == expected.shape
        assert got.tobytes() == expected.tobytes()


def test_frames_between_grid_points_are_the_array_expressions_to_the_last_bit() -> None:
    """The compiled sampling and interpolation of ``Renderer.frames`` against the numpy
    expressions they replace, for output rates on and off the grid's."""
    rng = np.random.default_rng(9)
    for fps, rate in [(60.0, 120.0), (30.0, 120.0), (59.94, 120.0), (25.0, 100.0), (48.0, 120.0)]:
        first = int(rng.integers(0, 500))
        times = np.arange(first, first + int(rng.integers(1, 40)), dtype=np.float64) / fps
        position = times * rate
        low = np.floor(position + 1e-9).astype(np.int64)
        fraction = np.where(position - low > 1e-9, position - low, 0.0)
        top = max(int(low[-1] + (fraction[-1] > 0)), int((low + (fraction > 0)).max()))
        got_low, got_fraction, got_top = _sampled(times, rate)
        assert got_low.tolist() == low.tolist() and got_top == top
        assert got_fraction.tobytes() == fraction.tobytes()
        grid = rng.normal(size=(top - int(low[0]) + 1, 6))
        base = grid[low - low[0]]
        following = grid[np.minimum(low + 1, top) - low[0]]
        expected = base + fraction[:, None] * (following - base)
        assert _interpolated(grid, low, fraction, top).tobytes() == expected.tobytes()


def _database() -> NodeDatabase:
    """Node 0 (AA, 5 frames rising 0..4) captured before node 1 (B, 5 frames at 10); node 2
    (B, 5 frames at 20) has no predecessor."""
    frames = np.concatenate([np.arange(5.0), np.full(5, 10.0), np.full(5, 20.0)])[:, None]
    aa, b = PHONEME_INDEX["AA"], PHONEME_INDEX["B"]
    return NodeDatabase(
        phoneme=np.array([aa, b, b]),
        emotion=np.zeros(3, dtype=np.int64),
        previous=np.full(3, PHONEME_INDEX["sil"]),
        next=np.full(3, PHONEME_INDEX["sil"]),
        pre=np.array([-1, 0, -1]),
        suc=np.array([1, -1, -1]),
        offsets=np.array([0, 5, 10, 15]),
        frames=frames,
        fps=10.0,
    )


SPANS = [
    PhonemeSpan("sil", 0.0, 1.0),
    PhonemeSpan("AA", 1.0, 2.0),
    PhonemeSpan("B", 2.0, 3.0),
    PhonemeSpan("sil", 3.0, 4.0),
]


def test_captured_neighbours_are_warped_and_not_smoothed() -> None:
    renderer = Renderer(_database(), np.zeros(1), 10.0, 3, 1.0)
    grid = renderer.grid(SPANS, [-1, 0, 1, -1], 0, 40)[:, 0]
    # AA over 1.0..2.0: node 0 warped from 5 frames (0..4) onto 10 points: 4 * u
    np.testing.assert_allclose(grid[10:20], 4.0 * np.arange(10) / 10, atol=1e-12)
    np.testing.assert_allclose(grid[20:30], 10.0)
    # the leading silence holds node 0's first frame; the trailing one node 1's last
    np.testing.assert_allclose(grid[:10], 0.0)
    np.testing.assert_allclose(grid[30:], 10.0)


def test_a_join_without_capture_is_smoothed_and_a_silence_is_a_line() -> None:
    renderer = Renderer(_database(), np.zeros(1), 10.0, 3, 1.0)
    path = [-1, 0, 2, -1]
    grid = renderer.grid(SPANS, path, 0, 40)[:, 0]
    raw = np.concatenate([4.0 * np.arange(10) / 10, np.full(10, 20.0)])
    changed = np.flatnonzero(np.abs(grid[10:30] - raw) > 1e-9) + 10
    assert changed.min() >= 17 and changed.max() <= 22  # three points each side of t = 2 s
    weights = np.array([1.0] * 3 + [2.0] * 3)  # AA intermediate, B highly visible
    np.testing.assert_allclose(grid[17:23], smooth_join(raw[7:13, None], weights, 1.0)[:, 0])
    np.testing.assert_allclose(grid[30:40], 20.0)  # a final silence holds the last frame
    inner = [PhonemeSpan("AA", 0.0, 1.0), PhonemeSpan("sil", 1.0, 2.0), PhonemeSpan("B", 2.0, 3.0)]
    line = renderer.grid(inner, [0, -1, 2], 0, 30)[:, 0]
    # from node 0's last frame (4), ending one segment, to node 2's first (20), starting the next
    np.testing.assert_allclose(line[10:20], 4.0 + 16.0 * np.arange(10) / 10)


def test_adjacent_silences_are_one_line_between_the_segments() -> None:
    renderer = Renderer(_database(), np.zeros(1), 10.0, 3, 1.0)
    spans = [
        PhonemeSpan("AA", 0.0, 1.0),
        PhonemeSpan("sil", 1.0, 1.5),
        PhonemeSpan("sil", 1.5, 2.0),
        PhonemeSpan("B", 2.0, 3.0),
    ]
    line = renderer.grid(spans, [0, -1, -1, 2], 0, 30)[:, 0]
    np.testing.assert_allclose(line[10:20], 4.0 + 16.0 * np.arange(10) / 10)


def test_frames_between_grid_points_are_linear() -> None:
    renderer = Renderer(_database(), np.zeros(1), 10.0, 3, 1.0)
    times = np.array([1.25, 1.5, 4.0])
    frames = renderer.frames(SPANS, [-1, 0, 1, -1], times)[:, 0]
    grid = renderer.grid(SPANS, [-1, 0, 1, -1], 0, 40)[:, 0]
    np.testing.assert_allclose(frames, [(grid[12] + grid[13]) / 2, grid[15], grid[40]])
