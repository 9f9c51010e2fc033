"""The warm-started active-set NNLS against scipy.optimize.nnls (Householder Lawson–Hanson).

Tolerances: on a random Gaussian A of full column rank (condition number at most about
1e3 here) the optimum is unique and both solvers reach it to about cond·eps; 1e-9 absolute
on x leaves a thousandfold margin over the 2e-12 seen. With more columns than rows the
optimal point A x is unique but x is not, so residual norms are compared instead, and the
KKT conditions checked directly (x ≥ 0, dual Aᵀ(y − A x) ≤ 0 off the support and 0 on it).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import nnls

from lipstream.numerics.nnls import cold_passive, nnls_system, solve_nnls, solve_nnls_rows

SOLUTION_ATOL = 1e-9
RESIDUAL_ATOL = 1e-9


def problems(seed: int, count: int, full_rank: bool) -> list[tuple[np.ndarray, np.ndarray]]:
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(count):
        rows = int(rng.integers(2, 30))
        columns = int(rng.integers(1, rows + 1)) if full_rank else int(rng.integers(rows + 1, 90))
        out.append((rng.normal(size=(rows, columns)), rng.normal(size=rows)))
    return out


def random_set(rng: np.random.Generator, size: int, share: float) -> np.ndarray:
    return np.asarray(rng.random(size) < share, dtype=np.bool_)


def assert_kkt(matrix: np.ndarray, target: np.ndarray, x: np.ndarray) -> None:
    dual = matrix.T @ (target - matrix @ x)
    assert (x >= 0).all() and np.isfinite(x).all()
    assert dual.max() <= 1e-9
    np.testing.assert_allclose(dual[x > 0], 0.0, atol=1e-9)


def residual(matrix: np.ndarray, target: np.ndarray, x: np.ndarray) -> float:
    return float(np.linalg.norm(matrix @ x - target))


def test_full_rank_problems_match_scipy_cold_and_from_wrong_active_sets() -> None:
    rng = np.random.default_rng(7)
    for matrix, target in problems(0, 200, full_rank=True):
        expected, _ = nnls(matrix, target)
        system = nnls_system(matrix)
        np.testing.assert_allclose(solve_nnls(system, target), expected, atol=SOLUTION_ATOL)
        for wrong in (random_set(rng, matrix.shape[1], 0.5), np.ones(matrix.shape[1], bool)):
            passive = wrong.copy()
            found = solve_nnls(system, target, passive)
            np.testing.assert_allclose(found, expected, atol=SOLUTION_ATOL)
            np.testing.assert_array_equal(passive, found > 0)


def test_more_columns_than_rows_reach_scipys_residual_and_the_kkt_conditions() -> None:
    rng = np.random.default_rng(8)
    for matrix, target in problems(1, 200, full_rank=False):
        expected, _ = nnls(matrix, target)
        system = nnls_system(matrix)
        for passive in (None, random_set(rng, matrix.shape[1], 0.3)):
            found = solve_nnls(system, target, passive)
            assert residual(matrix, target, found) == pytest.approx(
                residual(matrix, target, expected), abs=RESIDUAL_ATOL
            )
            assert_kkt(matrix, target, found)


def test_duplicated_and_zero_columns_are_left_out_without_changing_the_optimum() -> None:
    rng = np.random.default_rng(9)
    for _ in range(100):
        base = rng.normal(size=(12, 6))
        matrix = np.hstack([base, base[:, [0, 3]], np.zeros((12, 1)), 2.0 * base[:, [1]]])
        target = rng.normal(size=12)
        expected, _ = nnls(matrix, target)
        found = solve_nnls(nnls_system(matrix), target, np.ones(matrix.shape[1], bool))
        assert found[8] == 0.0
        assert residual(matrix, target, found) == pytest.approx(
            residual(matrix, target, expected), abs=RESIDUAL_ATOL
        )
        assert_kkt(matrix, target, found)


def test_a_target_in_the_cone_is_reproduced_exactly_enough() -> None:
    rng = np.random.default_rng(10)
    matrix = rng.normal(size=(20, 8))
    known = np.array([0.0, 1.5, 0.0, 0.2, 3.0, 0.0, 0.0, 0.7])
    np.testing.assert_allclose(solve_nnls(nnls_system(matrix), matrix @ known), known, atol=1e-12)


def test_a_zero_target_gives_zero_and_an_empty_active_set() -> None:
    system = nnls_system(np.random.default_rng(11).normal(size=(10, 30)))
    passive = np.ones(30, bool)
    found = solve_nnls(system, np.zeros(10), passive)
    np.testing.assert_array_equal(found, np.zeros(30))
    assert not passive.any()


def test_rows_are_solved_in_order_each_from_the_set_before() -> None:
    rng = np.random.default_rng(12)
    matrix = rng.normal(size=(15, 10))
    targets = rng.normal(size=(6, 15))
    system = nnls_system(matrix)
    out = np.full((6, 10), -1.0)
    passive = cold_passive(system)
    solve_nnls_rows(system, targets, np.array([0, 2, 5], dtype=np.intp), passive, out)
    for row in (0, 2, 5):
        np.testing.assert_allclose(out[row], nnls(matrix, targets[row])[0], atol=SOLUTION_ATOL)
    np.testing.assert_array_equal(out[[1, 3, 4]], -1.0)
    np.testing.assert_array_equal(passive, out[5] > 0)


def test_non_finite_inputs_are_refused() -> None:
    with pytest.raises(ValueError, match="design matrix"):
        nnls_system(np.array([[1.0, np.nan]]))
    with pytest.raises(ValueError, match="target"):
        solve_nnls(nnls_system(np.eye(2)), np.array([np.inf, 0.0]))
    with pytest.raises(ValueError, match="target"):
        solve_nnls(nnls_system(np.eye(2)), np.zeros(3))
