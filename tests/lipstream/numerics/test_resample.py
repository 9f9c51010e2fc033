"""Linear resampling against np.interp per channel and hand-computed rows."""

from __future__ import annotations

import numpy as np
import pytest

from lipstream.numerics.resample import (
    blend_into,
    bracket,
    extend_into,
    interp_columns,
    sample_curves,
)


def _interp_per_channel(rows: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """``rows`` (n, K) sampled at row indices 0 .. n − 1, read at ``positions``."""
    grid = np.arange(len(rows), dtype=np.float64)
    return np.stack([np.interp(positions, grid, rows[:, c]) for c in range(rows.shape[1])], 1)


def test_bracket_by_hand() -> None:
    assert bracket(2.25, 5) == (2, 3, 0.25)
    assert bracket(0.0, 5) == (0, 1, 0.0)
    assert bracket(3.0, 5) == (3, 4, 0.0)
    assert bracket(5.0, 5) == (5, 5, 0.0)
    assert bracket(0.0, 0) == (0, 0, 0.0)


def test_blend_and_extend_by_hand() -> None:
    rows = np.array([[1.0, -2.0], [3.0, 6.0]])
    out = np.empty(2)
    blend_into(out, rows, 0, 1, 0.25)
    assert out.tolist() == [1.5, 0.0]
    extend_into(out, rows, 0, 1, 0.25)
    assert out.tolist() == [1.5, 0.0]
    extend_into(out, rows, 0, 1, 1.5)  # the line continues past the second row
    assert out.tolist() == [4.0, 10.0]
    extend_into(out, rows, 0, 1, -0.5)
    assert out.tolist() == [0.0, -6.0]


def test_the_two_formulas_round_differently() -> None:
    """Why both are kept: a·(1 − w) + b·w and a + w·(b − a) differ in the last bit here, so
    a caller cannot switch formulas without changing its frames."""
    rows = np.array([[0.1], [0.7]])
    blended, extended = np.empty(1), np.empty(1)
    blend_into(blended, rows, 0, 1, 0.3)
    extend_into(extended, rows, 0, 1, 0.3)
    assert blended[0] == 0.1 * (1.0 - 0.3) + 0.7 * 0.3
    assert extended[0] == 0.1 + 0.3 * (0.7 - 0.1)
    assert blended[0] != extended[0]


def test_blend_is_exact_at_both_ends_and_extend_at_the_first() -> None:
    generator = np.random.default_rng(3)
    rows = generator.normal(size=(2, 50))
    out = np.empty(50)
    blend_into(out, rows, 0, 1, 0.0)
    assert out.tobytes() == rows[0].tobytes()
    blend_into(out, rows, 0, 1, 1.0)
    assert out.tobytes() == rows[1].tobytes()
    extend_into(out, rows, 0, 1, 0.0)
    assert out.tobytes() == rows[0].tobytes()


def test_float32_rows_are_widened_and_the_result_stored_in_the_outputs_dtype() -> None:
    generator = np.random.default_rng(4)
    rows = generator.normal(size=(2, 40)).astype(np.float32)
    wide = rows.astype(np.float64)
    weight = 0.37
    blended = np.empty(40, dtype=np.float32)
    blend_into(blended, rows, 0, 1, weight)
    expected = (wide[0] * (1.0 - weight) + wide[1] * weight).astype(np.float32)
    assert blended.tobytes() == expected.tobytes()
    extended = np.empty(40)
    extend_into(extended, rows, 1, 0, weight)
    assert extended.tobytes() == (wide[1] + weight * (wide[0] - wide[1])).tobytes()


@pytest.mark.parametrize("seed", range(4))
def test_sample_curves_equals_np_interp_per_channel(seed: int) -> None:
    generator = np.random.default_rng(seed)
    counts = generator.integers(1, 9, size=6)
    offsets = np.concatenate([[0], np.cumsum(counts)])
    values = generator.normal(size=(int(offsets[-1]), 3))
    relative = np.concatenate([[0.0, 1.0], generator.uniform(0.0, 1.0, 9)])
    positions = relative[None, :] * (counts[:, None] - 1)
    got = sample_curves(values, offsets, positions)
    assert got.shape == (6, 11, 3)
    for curve in range(6):
        rows = values[offsets[curve] : offsets[curve + 1]]
        expected = _interp_per_channel(rows, positions[curve])
        np.testing.assert_allclose(got[curve], expected, rtol=0, atol=1e-12)
        assert got[curve, 0].tobytes() == rows[0].tobytes()  # the first row, exactly
        assert got[curve, 1].tobytes() == rows[-1].tobytes()  # the last row, exactly


def test_sample_curves_on_grid_points_and_a_one_row_curve() -> None:
    values = np.array([[0.0, 10.0], [1.0, 20.0], [4.0, 40.0], [7.0, -1.0]])
    offsets = np.array([0, 3, 4])
    positions = np.array([[0.0, 1.0, 2.0, 0.5], [0.0, 0.0, 0.0, 0.0]])
    got = sample_curves(values, offsets, positions)
    assert got[0].tolist() == [[0.0, 10.0], [1.0, 20.0], [4.0, 40.0], [0.5, 15.0]]
    assert got[1].tolist() == [[7.0, -1.0]] * 4


def test_interp_columns_equals_np_interp_and_holds_the_ends() -> None:
    known = np.array([0.0, 0.5, 2.0])
    values = np.array([[1.0, 0.0], [2.0, -4.0], [5.0, 2.0]])
    times = np.array([-1.0, 0.0, 0.25, 0.5, 1.25, 2.0, 3.0])
    got = interp_columns(times, known, values)
    expected = [[1.0, 0.0], [1.0, 0.0], [1.5, -2.0], [2.0, -4.0], [3.5, -1.0], [5.0, 2.0]]
    assert got.tolist() == [*expected, [5.0, 2.0]]
    one = interp_columns(times, known[:1], values[:1])
    assert one.tolist() == [[1.0, 0.0]] * len(times)
    assert interp_columns(times, known, values[:, :0]).shape == (len(times), 0)
