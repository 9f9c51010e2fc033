"""Non-negative least squares, min ‖A x − y‖² over x ≥ 0, warm-started for a fixed A.

Method: Lawson and Hanson's active-set algorithm (Solving Least Squares Problems, 1974,
ch. 23), the one ``scipy.optimize.nnls`` runs, arranged for many right-hand sides y with
one design matrix A (m, K). The passive set P holds the variables free to be positive; the
others are held at 0. With x the least-squares solution on P (every x_P > 0), the dual
w = Aᵀ(y − A x) tells whether x is optimal (w_j ≤ 0 off P, the KKT conditions); if not,
the variable of largest w_j joins P, and an inner loop solves on P again, stepping back
along the segment to the new solution and dropping the variables that reach 0 whenever
the new solution is not positive. Each solve on P factors the precomputed Gram block
(AᵀA)_PP by Cholesky and refines the solution once with A itself (the corrected
semi-normal equations), so a solve costs the small factorisation plus two products with
A_P. A column that the Cholesky finds dependent on P (its pivot below a relative floor)
never enters P. That floor is the price of the Gram matrix: a column within about 3e-7
radians of the span of P is dependent here, where scipy's Householder QR resolves angles
down to about 1e-14 and may use such a column with a large weight; the optimum found is
then optimal for A with that column's tiny independent part left out.

Warm start: consecutive frames of a stream are alike, so the passive set of the last
solution is a good guess for the next. The solve starts from it: the least-squares
solution on that set, dropping the variables that come out non-positive until the rest
are all positive (a feasible start for Lawson–Hanson), then the outer loop above checks
the dual; when the guess was right, that is one factorisation and no iteration. Any start
ends at an optimum; when A has full column rank the optimum is unique, so a warm start
changes the answer by rounding only. When it has not (more keys than channels), the point
A x is still unique but x may not be: a solve returns an optimum whose residual equals
any other's, possibly another x than a cold start's.

Shapes: ``NnlsSystem.matrix`` A (m, K), ``transposed`` Aᵀ (K, m), ``gram`` AᵀA (K, K);
a passive set is a (K,) bool array, updated in place to the solution's.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
IndexArray = NDArray[np.intp]

_DEPENDENT = 1e-13
"""A column whose Cholesky pivot is below this fraction of its squared norm is dependent on
the passive columns (its angle to their span is under about 3e-7 radians): a few times
K·eps for K up to a few hundred, the rounding of a pivot computed from the Gram matrix."""
_DUAL_FLOOR = 64.0 * np.finfo(np.float64).eps
"""The dual w_j counts as positive above this times max(m, K) ‖A‖ ‖y‖ (rounding in Aᵀr)."""


class NnlsSystem(NamedTuple):
    """A design matrix A (m, K) with its transpose (K, m) and Gram matrix AᵀA (K, K), all
    float64 C-contiguous, built by ``nnls_system``."""

    matrix: FloatArray
    transposed: FloatArray
    gram: FloatArray


def nnls_system(matrix: FloatArray) -> NnlsSystem:
    """The NNLS system of a finite design matrix A (m, K); ValueError otherwise."""
    a = np.ascontiguousarray(matrix, dtype=np.float64)
    if a.ndim != 2 or 0 in a.shape or not np.isfinite(a).all():
        raise ValueError(f"an NNLS design matrix is finite, 2-D and not empty, got {a.shape}")
    return NnlsSystem(a, np.ascontiguousarray(a.T), np.ascontiguousarray(a.T @ a))


def cold_passive(system: NnlsSystem) -> BoolArray:
    """A passive set with every variable held at 0: a cold start."""
    return np.zeros(system.gram.shape[0], dtype=np.bool_)


def solve_nnls(
    system: NnlsSystem, target: FloatArray, passive: BoolArray | None = None
) -> FloatArray:
    """x ≥ 0 (K,) minimising ‖A x − target‖ for a finite ``target`` (m,), started from
    ``passive`` (K,) bool (cold when None; updated in place to the solution's set)."""
    y = np.ascontiguousarray(target, dtype=np.float64)
    if y.shape != (system.matrix.shape[0],) or not np.isfinite(y).all():
        raise ValueError(f"an NNLS target is finite with shape {(system.matrix.shape[0],)}")
    state = cold_passive(system) if passive is None else passive
    out = np.zeros((1, system.gram.shape[0]))
    solve_nnls_rows(system, y[None], np.zeros(1, dtype=np.intp), state, out)
    solution: FloatArray = out[0]
    return solution


def warm_nnls() -> None:
    """Compile (or load from numba's cache) ``solve_nnls_rows`` for the argument types every
    caller passes, so a stream's first bounded frame does not pay for it."""
    solve_nnls(nnls_system(np.array([[1.0, 1.0], [0.0, 1.0]])), np.array([1.0, -1.0]))


@njit(cache=True)
def solve_nnls_rows(
    system: NnlsSystem,
    targets: FloatArray,
    rows: IndexArray,
    passive: BoolArray,
    out: FloatArray,
) -> None:
    """Solve each ``targets[row]`` (m,) for ``row`` in ``rows``, in order, into ``out[row]``
    (K,); each solve starts from the passive set the previous one ended with (``passive``,
    (K,) bool, updated in place). Targets must be finite. A warm start that does not
    converge within 3K steps (as scipy's limit) is retried cold."""
    n_keys = system.gram.shape[0]
    work = _Workspace(
        np.empty(n_keys, dtype=np.intp),
        np.empty((n_keys, n_keys)),
        np.empty(n_keys),
        np.empty(n_keys),
        np.empty(targets.shape[1]),
    )
    for row in rows:
        if not _solve(system, targets[row], passive, out[row], work):
            passive[:] = False
            _solve(system, targets[row], passive, out[row], work)


class _Workspace(NamedTuple):
    order: IndexArray  # passive variables, in the order of the Cholesky factor
    factor: FloatArray  # lower Cholesky factor of the Gram block, (K, K)
    solution: FloatArray  # least-squares solution on the passive set, by position in order
    scratch: FloatArray  # (K,)
    residual: FloatArray  # (m,)


@njit(cache=True)
def _solve(
    system: NnlsSystem, target: FloatArray, passive: BoolArray, x: FloatArray, work: _Workspace
) -> bool:
    """One Lawson–Hanson solve from ``passive`` into ``x``; False if it hit the step limit."""
    n_keys = system.gram.shape[0]
    order, z = work.order, work.solution
    count = 0
    for key in range(n_keys):
        if passive[key]:
            order[count] = key
            count += 1
    count = _feasible_start(system, target, count, work)
    x[:] = 0.0
    for position in range(count):
        x[order[position]] = z[position]
    floor = _DUAL_FLOOR * max(target.shape[0], n_keys) * _norm(target) * _largest_norm(system)
    refused = np.zeros(n_keys, dtype=np.bool_)
    converged = False
    for _ in range(3 * n_keys):
        entering = _entering(system, target, x, order, count, refused, floor, work)
        if entering < 0:
            converged = True
            break
        order[count] = entering
        grown = _factor(system.gram, order, count + 1, work.factor)
        if grown == count:
            refused[entering] = True
            continue
        _least_squares(system, target, grown, work)
        if z[grown - 1] <= 0.0:
            refused[entering] = True
            continue
        refused[:] = False
        count = _inner(system, target, x, grown, work)
    passive[:] = False
    for position in range(count):
        passive[order[position]] = True
    for key in range(n_keys):
        if not passive[key]:
            x[key] = 0.0
    return converged


@njit(cache=True)
def _feasible_start(system: NnlsSystem, target: FloatArray, count: int, work: _Workspace) -> int:
    """Shrink the first ``count`` of ``work.order`` until its least-squares solution is
    positive (dropping dependent and non-positive variables); the size left."""
    order, z = work.order, work.solution
    while count > 0:
        count = _factor(system.gram, order, count, work.factor)
        _least_squares(system, target, count, work)
        kept = 0
        for position in range(count):
            if z[position] > 0.0:
                order[kept] = order[position]
                z[kept] = z[position]
                kept += 1
        if kept == count:
            return count
        count = kept
    return 0


@njit(cache=True)
def _inner(
    system: NnlsSystem, target: FloatArray, x: FloatArray, count: int, work: _Workspace
) -> int:
    """Lawson–Hanson's inner loop from the solution ``work.solution`` on ``count`` passive
    variables: step back towards x until the solution is positive; ``x`` takes it, and the
    passive set's size is returned."""
    order, z = work.order, work.solution
    while True:
        step = 1.0
        blocking = -1
        for position in range(count):
            if z[position] <= 0.0:
                old = x[order[position]]
                ratio = old / (old - z[position])
                if ratio < step:
                    step, blocking = ratio, position
        if blocking < 0:
            for position in range(count):
                x[order[position]] = z[position]
            return count
        kept = 0
        for position in range(count):
            key = order[position]
            value = x[key] + step * (z[position] - x[key])
            if position == blocking or value <= 0.0:
                x[key] = 0.0
            else:
                x[key] = value
                order[kept] = key
                kept += 1
        count = _factor(system.gram, order, kept, work.factor)
        _least_squares(system, target, count, work)


@njit(cache=True)
def _entering(
    system: NnlsSystem,
    target: FloatArray,
    x: FloatArray,
    order: IndexArray,
    count: int,
    refused: BoolArray,
    floor: float,
    work: _Workspace,
) -> int:
    """The held variable of largest dual w_j = a_jᵀ(y − A x) above ``floor``, or -1."""
    matrix, residual = system.matrix, work.residual
    for row in range(matrix.shape[0]):
        total = target[row]
        for position in range(count):
            key = order[position]
            total -= matrix[row, key] * x[key]
        residual[row] = total
    best, entering = floor, -1
    for key in range(matrix.shape[1]):
        if x[key] > 0.0 or refused[key]:
            continue
        dual = 0.0
        for row in range(matrix.shape[0]):
            dual += system.transposed[key, row] * residual[row]
        if dual > best:
            best, entering = dual, key
    return entering


@njit(cache=True)
def _factor(gram: FloatArray, order: IndexArray, count: int, factor: FloatArray) -> int:
    """Cholesky factor of the Gram block of ``order[:count]`` into ``factor``, leaving out (and
    compacting ``order`` past) each column dependent on those before it; the size kept."""
    kept = 0
    for position in range(count):
        key = order[position]
        for column in range(kept):
            total = gram[key, order[column]]
            for inner in range(column):
                total -= factor[kept, inner] * factor[column, inner]
            factor[kept, column] = total / factor[column, column]
        pivot = gram[key, key]
        for column in range(kept):
            pivot -= factor[kept, column] ** 2
        if pivot <= _DEPENDENT * gram[key, key] or pivot <= 0.0:
            continue
        factor[kept, kept] = np.sqrt(pivot)
        order[kept] = key
        kept += 1
    return kept


@njit(cache=True)
def _least_squares(system: NnlsSystem, target: FloatArray, count: int, work: _Workspace) -> None:
    """Least squares on ``order[:count]`` into ``work.solution``: the semi-normal equations
    R Rᵀ z = A_Pᵀ y, then one correction with the residual y − A_P z."""
    order, z, correction = work.order, work.solution, work.scratch
    _normal_rhs(system, target, order, count, z)
    _cholesky_solve(work.factor, count, z)
    matrix, residual = system.matrix, work.residual
    for row in range(matrix.shape[0]):
        total = target[row]
        for position in range(count):
            total -= matrix[row, order[position]] * z[position]
        residual[row] = total
    _normal_rhs(system, residual, order, count, correction)
    _cholesky_solve(work.factor, count, correction)
    for position in range(count):
        z[position] += correction[position]


@njit(cache=True)
def _normal_rhs(
    system: NnlsSystem, vector: FloatArray, order: IndexArray, count: int, out: FloatArray
) -> None:
    for position in range(count):
        key = order[position]
        total = 0.0
        for row in range(vector.shape[0]):
            total += system.transposed[key, row] * vector[row]
        out[position] = total


@njit(cache=True)
def _cholesky_solve(factor: FloatArray, count: int, rhs: FloatArray) -> None:
    """Solve L Lᵀ z = rhs in place for the leading ``count`` block of ``factor``."""
    for row in range(count):
        total = rhs[row]
        for column in range(row):
            total -= factor[row, column] * rhs[column]
        rhs[row] = total / factor[row, row]
    for row in range(count - 1, -1, -1):
        total = rhs[row]
        for column in range(row + 1, count):
            total -= factor[column, row] * rhs[column]
        rhs[row] = total / factor[row, row]


@njit(cache=True)
def _norm(vector: FloatArray) -> float:
    total = 0.0
    for value in vector:
        total += value * value
    return float(np.sqrt(total))


@njit(cache=True)
def _largest_norm(system: NnlsSystem) -> float:
    largest = 0.0
    for key in range(system.gram.shape[0]):
        largest = max(largest, system.gram[key, key])
    return float(np.sqrt(largest))
