"""The banded windowed least squares against dense solves built independently."""

from __future__ import annotations

import numpy as np
import pytest

from lipstream.numerics.banded import (
    factor_spd_banded,
    solve_spd_banded,
    solve_spd_block_tridiagonal,
    solve_with_factor,
    windowed_least_squares,
)


def window_matrix(stencil: np.ndarray, frames: int) -> np.ndarray:
    """Dense rows of W for the frames whose stencil fits, one row per such frame."""
    half = len(stencil) // 2
    rows = []
    for centre in range(half, frames - half):
        row = np.zeros(frames)
        row[centre - half : centre + half + 1] = stencil
        rows.append(row)
    return np.array(rows).reshape(-1, frames)


def dense_solution(
    windows: list[np.ndarray], means: np.ndarray, precisions: np.ndarray
) -> np.ndarray:
    """Stack every window row over time ⊗ dimensions and solve the weighted normal equations."""
    _, frames, dims = means.shape
    normal = np.zeros((frames * dims, frames * dims))
    rhs = np.zeros(frames * dims)
    for stencil, mean, precision in zip(windows, means, precisions, strict=True):
        half = len(stencil) // 2
        for row_index, row in enumerate(window_matrix(np.asarray(stencil, float), frames)):
            centre = row_index + half
            lifted = np.kron(row[:, None], np.eye(dims)).T  # (D, T·D), time-major
            weight = precision[centre] if precision.ndim == 3 else np.diag(precision[centre])
            normal += lifted.T @ weight @ lifted
            rhs += lifted.T @ weight @ mean[centre]
    return np.linalg.solve(normal, rhs).reshape(frames, dims)


def random_spd(rng: np.random.Generator, count: int, dims: int) -> np.ndarray:
    factors = rng.normal(size=(count, dims, dims))
    return factors @ factors.transpose(0, 2, 1) + 0.1 * np.eye(dims)


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("diagonal", [False, True])
def test_matches_a_dense_solve(seed: int, diagonal: bool) -> None:
    rng = np.random.default_rng(seed)
    frames, dims = int(rng.integers(6, 14)), int(rng.integers(1, 4))
    windows = [np.array([1.0]), np.array([-0.5, 0.0, 0.5])]
    if seed % 2:
        windows.append(np.array([0.3, -1.0, 2.0, -1.0, 0.3]))
    means = rng.normal(size=(len(windows), frames, dims))
    if diagonal:
        precisions = rng.uniform(0.2, 3.0, size=(len(windows), frames, dims))
    else:
        precisions = np.stack([random_spd(rng, frames, dims) for _ in windows])
    got = windowed_least_squares(windows, means, precisions)
    np.testing.assert_allclose(got, dense_solution(windows, means, precisions), atol=1e-9)


def test_position_only_reproduces_the_targets() -> None:
    means = np.arange(12.0).reshape(1, 6, 2)
    got = windowed_least_squares([np.array([1.0])], means, np.ones((1, 6, 2, 2)) * np.eye(2))
    np.testing.assert_allclose(got, means[0])


def test_curvature_penalty_leaves_a_straight_line_alone() -> None:
    line = np.linspace(-1.0, 2.0, 20)[:, None]
    means = np.stack([line, np.zeros_like(line)])
    precisions = np.stack([np.ones_like(line), np.full_like(line, 50.0)])
    got = windowed_least_squares([np.array([1.0]), np.array([1.0, -2.0, 1.0])], means, precisions)
    np.testing.assert_allclose(got, line, atol=1e-10)


def test_a_frame_without_precision_is_refused() -> None:
    precisions = np.ones((1, 5, 1))
    precisions[0, 2] = 0.0
    with pytest.raises(np.linalg.LinAlgError, match="not positive definite"):
        windowed_least_squares([np.array([1.0])], np.zeros((1, 5, 1)), precisions)


def test_solve_spd_banded_matches_dense() -> None:
    rng = np.random.default_rng(3)
    size, width = 9, 2
    dense = np.zeros((size, size))
    for offset in range(width + 1):
        values = rng.uniform(-0.3, 0.3, size - offset)
        dense += np.diag(values, -offset) + (np.diag(values, offset) if offset else 0)
    dense += 2.0 * np.eye(size)
    bands = np.array([np.pad(np.diag(dense, -k), (0, k)) for k in range(width + 1)])
    rhs = rng.normal(size=(size, 2))
    np.testing.assert_allclose(solve_spd_banded(bands, rhs), np.linalg.solve(dense, rhs))


def banded_system(rng: np.random.Generator, size: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """A dense SPD matrix of ``width`` sub-diagonals (a sum of random Gram terms over windows
    of width + 1 unknowns, plus a small ridge) and its lower bands in LAPACK storage."""
    dense = 0.05 * np.eye(size)
    for start in range(size - width):
        rows = rng.normal(size=(width + 1, width + 1))
        dense[start : start + width + 1, start : start + width + 1] += rows.T @ rows
    bands = np.array([np.pad(np.diag(dense, -k), (0, k)) for k in range(width + 1)])
    return dense, bands


@pytest.mark.parametrize(("size", "width"), [(1, 0), (6, 1), (12, 2), (20, 5)])
def test_a_factor_solves_many_right_hand_sides_as_a_dense_solve(size: int, width: int) -> None:
    rng = np.random.default_rng(size + width)
    dense, bands = banded_system(rng, max(size, width + 1), width)
    factor = factor_spd_banded(bands)
    assert factor is not None
    assert not factor.lower.flags.writeable
    for shape in [(len(dense),), (len(dense), 3)]:
        rhs = rng.normal(size=shape)
        solution = solve_with_factor(factor, rhs)
        np.testing.assert_allclose(solution, np.linalg.solve(dense, rhs), rtol=1e-8, atol=1e-10)
        if width != 1:  # scipy solves a tridiagonal band by dptsv (LDLᵀ), not dpbsv
            assert np.array_equal(solution, solve_spd_banded(bands, rhs))


def test_a_matrix_that_cannot_be_factored_has_no_factor() -> None:
    rng = np.random.default_rng(8)
    dense, bands = banded_system(rng, 7, 2)
    indefinite = bands.copy()
    indefinite[0, 4] = -1.0
    assert factor_spd_banded(indefinite) is None
    with pytest.raises(np.linalg.LinAlgError, match="not positive definite"):
        solve_spd_banded(indefinite, np.ones(7))
    infinite = bands.copy()
    infinite[1, 2] = np.inf
    assert factor_spd_banded(infinite) is None
    assert factor_spd_banded(bands) is not None


def test_solving_with_a_factor_refuses_a_bad_right_hand_side() -> None:
    rng = np.random.default_rng(9)
    _, bands = banded_system(rng, 5, 1)
    factor = factor_spd_banded(bands)
    assert factor is not None
    with pytest.raises(ValueError, match="does not match"):
        solve_with_factor(factor, np.ones(4))
    with pytest.raises(ValueError, match="non-finite"):
        solve_with_factor(factor, np.array([1.0, np.nan, 0.0, 0.0, 0.0]))
    with pytest.raises(ValueError, match="bandwidth"):
        factor_spd_banded(np.ones(5))


def block_tridiagonal_system(
    rng: np.random.Generator, frames: int, dims: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A dense SPD block-tridiagonal matrix (a sum of random Gram terms over frame pairs, plus a
    small ridge) and its diagonal and below-diagonal blocks."""
    size = frames * dims
    dense = 0.05 * np.eye(size)
    for t in range(frames - 1):
        rows = rng.normal(size=(dims, 2 * dims))
        dense[t * dims : (t + 2) * dims, t * dims : (t + 2) * dims] += rows.T @ rows
    diagonal = np.array(
        [dense[t * dims : (t + 1) * dims, t * dims : (t + 1) * dims] for t in range(frames)]
    )
    below = np.zeros((frames - 1, dims, dims))
    for t in range(frames - 1):
        below[t] = dense[(t + 1) * dims : (t + 2) * dims, t * dims : (t + 1) * dims]
    return dense, diagonal, below


@pytest.mark.parametrize(("frames", "dims"), [(1, 3), (2, 1), (7, 2), (12, 5)])
def test_solve_spd_block_tridiagonal_matches_dense(frames: int, dims: int) -> None:
    rng = np.random.default_rng(frames * 10 + dims)
    dense, diagonal, below = block_tridiagonal_system(rng, frames, dims)
    rhs = rng.normal(size=(frames, dims))
    upper_ignored = diagonal.copy()
    upper_ignored[:, np.triu_indices(dims, 1)[0], np.triu_indices(dims, 1)[1]] = 99.0
    expected = np.linalg.solve(dense, rhs.reshape(-1)).reshape(frames, dims)
    np.testing.assert_allclose(solve_spd_block_tridiagonal(upper_ignored, below, rhs), expected)


def test_solve_spd_block_tridiagonal_refuses_an_indefinite_matrix() -> None:
    diagonal = np.stack([np.eye(2), np.eye(2), np.diag([1.0, -1.0])])
    below = np.zeros((2, 2, 2))
    with pytest.raises(np.linalg.LinAlgError, match="not positive definite.*frame 2"):
        solve_spd_block_tridiagonal(diagonal, below, np.ones((3, 2)))
    with pytest.raises(ValueError, match="does not fit"):
        solve_spd_block_tridiagonal(diagonal, below[:1], np.ones((3, 2)))
    with pytest.raises(ValueError, match="non-finite"):
        solve_spd_block_tridiagonal(diagonal, below, np.full((3, 2), np.inf))


def test_malformed_input_is_a_value_error() -> None:
    with pytest.raises(ValueError, match="odd length"):
        windowed_least_squares([np.array([1.0, 2.0])], np.zeros((1, 4, 1)), np.ones((1, 4, 1)))
    with pytest.raises(ValueError, match="means must be"):
        windowed_least_squares([np.array([1.0])], np.zeros((4, 1)), np.ones((1, 4, 1)))
    with pytest.raises(ValueError, match="non-finite"):
        solve_spd_banded(np.array([[np.nan, 1.0]]), np.ones(2))
