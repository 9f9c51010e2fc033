"""The fast search's step: min over the previous layer of φ(a) + TC(a, b) for each node b, exact.

Method. On the demo database nearly all of a join's cost is two terms: PNT when the
visemes of a and pre(b) differ (Table I) and the velocity gap ‖v_first(b) − v_last(a)‖;
the position gap (weighted by a small α3) and DSC add little. So the previous layer is
grouped by viseme, each group in ascending φ, and for a node b whose predecessor p has
viseme v:

1. the group of viseme v is scanned first, up to the first a with φ(a) ≥ best (TC ≥ 0);
   every other group adds PNT to every pair, so it is scanned up to the first a with
   φ(a) + PNT ≥ best (the costs add PNT after the gaps, and rounding is monotone, so a
   pair past that point cannot cost less than best as computed);
2. each pair's velocity gap is summed a few coordinates at a time, coordinates in
   descending variance over the database, and the pair is dropped as soon as
   φ(a) + penalty + the partial gap reaches best: a partial sum of squares never exceeds
   the whole. The comparison keeps a slack of 1e-12 · (|best| + 1), far above the
   rounding of the sums, so a dropped pair is one whose computed cost is at least best;
3. a pair that survives is priced whole: the position gap and the penalty, then DSC, each
   compared with best before the next; it replaces the best only when strictly cheaper.

A pair is skipped only when its cost as computed is no less than the best, so the optimum
is that of a scan pricing every pair: only the order among equal costs may differ, and the
velocity gap's rounding (its coordinates are summed in another order than ``costs.gap``'s,
a difference of about 1e-16 relative). Rule 1
(pre(b) in the previous layer: φ(pre) + 0 starts the best) and Rule 4 (no predecessor:
α1·PNT from the cheapest a) are taken without a scan.

The scan's bar is the best + ``SURE`` relative rather than the best: the same pairs
replace the best, in the same order, and the scan also knows whether the best beat every
other predecessor by that margin. ``fast_step`` ignores that; the fixed-lag stream's
step (``lag_step``, for ``lag_search``) keeps each best pair's cost terms, and takes the
best predecessor of a node the last window's step found, won by the margin, and that
descends from the committed node, summing its cost from the terms in the scan's order:
the scan's value, bit for bit.

Memory reads, more than arithmetic, set a priced pair's time: it read rows of six arrays
spread over the database. ``JoinRecords`` lays out, once per model at first use, each
node's leaving side (last velocity reordered, last position, DSC's leaving half) and
arriving side (first velocity reordered, first position, the arriving half of its
predecessor) as one contiguous row each, so a pair reads two rows front to back and a
scan touches only their first cache line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numba import njit

from .nodes import NodeDatabase, NodeFeatures

SLACK = 1e-12
"""Relative slack of the partial-gap test (far above the rounding of a 1e-16 sum)."""


@dataclass(frozen=True)
class JoinRecords:
    """Per node, (N, 2K + (M − 2)K) each: ``leaving`` = [last velocity in ``order``, last
    position, DSC's leaving half]; ``arriving`` = [first velocity in ``order``, first
    position, the arriving half of its predecessor (zeros without one)]. ``order``: the
    velocity coordinates in descending variance."""

    leaving: np.ndarray
    arriving: np.ndarray
    order: np.ndarray

    @property
    def dims(self) -> int:
        return len(self.order)

    @cached_property
    def natural(self) -> np.ndarray:
        """The column of each velocity coordinate, natural order (``order`` inverted)."""
        return np.argsort(self.order)

    @classmethod
    def of(cls, nodes: NodeDatabase, features: NodeFeatures) -> JoinRecords:
        spread = features.first_velocity.var(axis=0) + features.last_velocity.var(axis=0)
        order = np.argsort(-spread, kind="stable")
        n = nodes.size
        predecessor = np.where(nodes.pre[:, None, None] >= 0, features.arriving[nodes.pre], 0.0)
        leaving = np.hstack(
            [
                features.last_velocity[:, order],
                features.last_position,
                features.leaving.reshape(n, -1),
            ]
        )
        arriving = np.hstack(
            [features.first_velocity[:, order], features.first_position, predecessor.reshape(n, -1)]
        )
        return cls(np.ascontiguousarray(leaving), np.ascontiguousarray(arriving), order)


@njit(cache=True)
def _groups(prev_nodes: np.ndarray, viseme: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``members``: positions in the layer grouped by viseme, ascending φ within a group;
    ``starts`` (visemes + 1): each viseme's slice of ``members`` (empty when absent)."""
    classes = 0
    for a in prev_nodes:
        classes = max(classes, viseme[a] + 1)
    starts = np.zeros(classes + 1, dtype=np.int64)
    for a in prev_nodes:
        starts[viseme[a] + 1] += 1
    for v in range(classes):
        starts[v + 1] += starts[v]
    filled = starts[:-1].copy()
    members = np.empty(len(prev_nodes), dtype=np.int64)
    for i in range(len(prev_nodes)):
        v = viseme[prev_nodes[i]]
        members[filled[v]] = i
        filled[v] += 1
    return members, starts


@njit(cache=True, inline="always")
def _squares(
    leaving: np.ndarray, a: int, arriving: np.ndarray, b: int, start: int, stop: int
) -> float:
    total = 0.0
    for k in range(start, stop):
        difference = arriving[b, k] - leaving[a, k]
        total += difference * difference
    return total


@njit(cache=True, inline="always")
def _velocity_squares(
    leaving: np.ndarray, a: int, arriving: np.ndarray, b: int, dims: int, limit: float
) -> float:
    """Σ of the squared velocity differences, or a partial sum ≥ ``limit`` once one is
    (tested after 2, 4 and 8 coordinates)."""
    total = 0.0
    start = 0
    for stop in range(2, 9, 2):
        if stop == 6 or stop >= dims:
            continue
        total += _squares(leaving, a, arriving, b, start, stop)
        if total >= limit:
            return total
        start = stop
    return total + _squares(leaving, a, arriving, b, start, dims)


@njit(cache=True, inline="always")
def _dsc(leaving: np.ndarray, a: int, arriving: np.ndarray, b: int, dims: int) -> float:
    """Eq. 6 as ``costs.direct_smoothing``, from the records' halves (same sums, same order)."""
    interior = (leaving.shape[1] - 2 * dims) // dims
    total = 0.0
    for m in range(interior):
        base = 2 * dims + m * dims
        squares = 0.0
        for k in range(dims):
            value = leaving[a, base + k] + arriving[b, base + k]
            squares += value * value
        total += math.sqrt(squares)
    return float(total * (interior + 1))


SURE = 1e-9
"""Relative margin by which a scanned node's best predecessor beats every other one for the
fixed-lag search to reuse it in the next window (``lag_step``): far above the rounding of a
window's sums (about 1e-15 relative), so a rerooted window that lowers every cost by one
constant cannot reorder the two."""

PRICED, NATURAL, UNCAPTURED = 0, 1, 2
"""How a node's best predecessor was found (``lag_step``'s ``kind``): a priced pair, Rule 1
(its captured predecessor, TC = 0) or Rule 4 (no captured predecessor: the cheapest one)."""


@njit(cache=True, inline="always")
def _margin(best: float) -> float:
    return SURE * (abs(best) + 1.0)


@njit(cache=True, inline="always")
def _scan(
    members: np.ndarray, start: int, stop: int, penalty: float, best: float, arg: int,
    second: float, terms: np.ndarray, b: int, p: int, prev_nodes: np.ndarray,
    prev_f: np.ndarray, viseme: np.ndarray, leaving: np.ndarray, arriving: np.ndarray,
    dims: int, packed: np.ndarray,
) -> tuple[float, int, float]:  # fmt: skip
    """One viseme group (``members[start:stop]``, ascending φ), every pair adding
    ``penalty``, priced up to a bar of the best + ``_margin``: the same pairs replace the
    best, in the same order, as with the bar at the best, and ``second`` (the least other
    cost seen) is exact below the bar, so the best wins by the margin iff ``second`` ≥ the
    bar at the end. The best pair's terms of the cost, (α3·PGap, VGap, PNT or 0, α2·DSC),
    go to ``terms``."""
    bar = best + _margin(best)
    for k in range(start, stop):
        i = members[k]
        floor = prev_f[i] + penalty
        if floor >= bar:
            break
        a = prev_nodes[i]
        if a == p:
            continue
        budget = bar - floor + SLACK * (abs(bar) + 1.0)
        velocity = _velocity_squares(leaving, a, arriving, b, dims, budget * budget)
        if velocity >= budget * budget:
            continue
        position = _squares(leaving, a, arriving, b, dims, 2 * dims)
        gaps = packed[2] * math.sqrt(position)
        speed = math.sqrt(velocity)
        cost = prev_f[i] + gaps + speed
        penalised = viseme[a] != viseme[p]
        if penalised:
            cost += packed[3]
        if cost >= bar:
            continue
        smooth = packed[1] * _dsc(leaving, a, arriving, b, dims)
        cost += smooth
        if cost < best:
            second = min(second, best)
            best = cost
            arg = i
            bar = best + _margin(best)
            terms[0] = gaps
            terms[1] = speed
            terms[2] = packed[3] if penalised else 0.0
            terms[3] = smooth
        elif cost < second:
            second = cost
    return best, arg, second


@njit(cache=True)
def fast_step(
    prev_nodes: np.ndarray, prev_f: np.ndarray, next_nodes: np.ndarray, next_u: np.ndarray,
    pre: np.ndarray, viseme: np.ndarray, leaving: np.ndarray, arriving: np.ndarray,
    dims: int, packed: np.ndarray, position: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """``next_nodes`` in ascending φ, their φ, and the position of each one's best
    predecessor in ``prev_nodes`` (``prev_f`` ascending); ``leaving`` and ``arriving`` are
    ``JoinRecords``' rows, ``dims`` the motion basis's size; ``position`` (N) is scratch,
    all -1, and left so."""
    for i in range(len(prev_nodes)):
        position[prev_nodes[i]] = i
    members, starts = _groups(prev_nodes, viseme)
    classes = len(starts) - 1
    f = np.empty(len(next_nodes))
    back = np.empty(len(next_nodes), dtype=np.int64)
    terms = np.empty(4)  # the best pair's terms, which this step does not keep
    for j in range(len(next_nodes)):
        b = next_nodes[j]
        p = pre[b]
        if p < 0:
            f[j] = prev_f[0] + packed[0] + next_u[j]
            back[j] = 0
            continue
        best = np.inf
        arg = 0
        second = np.inf
        if position[p] >= 0:
            best = prev_f[position[p]]
            arg = position[p]
        own = viseme[p]
        if own < classes:
            best, arg, second = _scan(
                members, starts[own], starts[own + 1], 0.0, best, arg, second, terms, b, p,
                prev_nodes, prev_f, viseme, leaving, arriving, dims, packed,
            )  # fmt: skip
        for v in range(classes):
            if v != own and starts[v + 1] > starts[v]:
                best, arg, second = _scan(
                    members, starts[v], starts[v + 1], packed[3], best, arg, second, terms, b,
                    p, prev_nodes, prev_f, viseme, leaving, arriving, dims, packed,
                )  # fmt: skip
        f[j] = best + next_u[j]
        back[j] = arg
    for i in range(len(prev_nodes)):
        position[prev_nodes[i]] = -1
    order = np.argsort(f, kind="mergesort")
    return next_nodes[order], f[order], back[order]


ENTRY_VELOCITY = 4
"""Leading velocity coordinates (descending variance) an entry table holds per candidate."""


def entry_table(
    nodes: np.ndarray, unary: np.ndarray, pre: np.ndarray, viseme: np.ndarray,
    records: JoinRecords,
) -> np.ndarray:  # fmt: skip
    """Per candidate of a layer (``nodes``, their U in ``unary``), what ``best_entry`` reads
    for every one of them, contiguous, in ascending U (then position): [U, its position in
    ``nodes``, pre(b), viseme of pre(b) (−1 without one), the first ``ENTRY_VELOCITY``
    coordinates of its first velocity in ``records``' order]."""
    order = np.argsort(unary, kind="stable")
    chosen = nodes[order]
    before = pre[chosen]
    kept = min(ENTRY_VELOCITY, records.dims)
    table = np.empty((len(nodes), 4 + kept))
    table[:, 0] = unary[order]
    table[:, 1] = order
    table[:, 2] = before
    table[:, 3] = np.where(before >= 0, viseme[np.maximum(before, 0)], -1)
    table[:, 4:] = records.arriving[chosen, :kept]
    table.setflags(write=False)
    return table


@njit(cache=True, inline="always")
def _entry_floor(
    table: np.ndarray, row: int, a: int, own: int, leaving: np.ndarray, packed: np.ndarray
) -> float:
    """A floor under (0 + TC(a, b)) + U(b) for the table's ``row`` (b), own = viseme(a):
    U, U + α1·PNT (Rule 4), or U (+ PNT when the visemes differ) + the gap of the table's
    velocity coordinates; exact up to rounding (``SLACK`` covers it)."""
    floor = table[row, 0]
    p = int(table[row, 2])
    if p < 0:
        return float(floor + packed[0])
    if p == a:
        return float(floor)
    if int(table[row, 3]) != own:
        floor += packed[3]
    squares = 0.0
    for k in range(table.shape[1] - 4):
        difference = table[row, 4 + k] - leaving[a, k]
        squares += difference * difference
    return float(floor + math.sqrt(squares))


@njit(cache=True, inline="always")
def _exact_tc(
    a: int, b: int, p: int, viseme: np.ndarray, leaving: np.ndarray, arriving: np.ndarray,
    natural: np.ndarray, dims: int, packed: np.ndarray,
) -> float:  # fmt: skip
    """``costs.transition_cost(a, b)`` for p = pre(b) ≥ 0, p ≠ a, from ``JoinRecords``' rows:
    every sum in ``transition_cost``'s order (velocity coordinates read at ``natural``, the
    records' column of each coordinate), so the same value to the last bit."""
    position = 0.0
    for k in range(dims):
        difference = arriving[b, dims + k] - leaving[a, dims + k]
        position += difference * difference
    velocity = 0.0
    for k in range(dims):
        difference = arriving[b, natural[k]] - leaving[a, natural[k]]
        velocity += difference * difference
    cost = packed[2] * math.sqrt(position)
    cost += math.sqrt(velocity)
    if viseme[a] != viseme[p]:
        cost += packed[3]
    return float(cost + packed[1] * _dsc(leaving, a, arriving, b, dims))


@njit(cache=True)
def best_entry(
    a: int, nodes: np.ndarray, table: np.ndarray, viseme: np.ndarray, leaving: np.ndarray,
    arriving: np.ndarray, natural: np.ndarray, packed: np.ndarray,
) -> tuple[int, float, float]:  # fmt: skip
    """The position j in ``nodes`` (``table`` = their ``entry_table``) of the least
    (0 + TC(a, b)) + U(b), b = nodes[j], the lowest j among equal costs, that cost and its
    TC: the exact step from the one node ``a`` (``search._exact_kernel``) and its argmin.

    The table runs in ascending U. A first pass prices first the pair of least floor
    (``_entry_floor``) among those of U below the least floor so far (the pair of Rule 1,
    b = suc(a), has floor U(b) and its cost); the second stops at the first U above the
    best (TC ≥ 0), drops a pair whose floor exceeds the best (with ``SLACK``, as in
    ``_scan``) and prices the rest exactly (``_exact_tc``)."""
    own = viseme[a]
    seed = 0
    lowest = np.inf
    for row in range(len(table)):
        if table[row, 0] >= lowest:
            break
        floor = _entry_floor(table, row, a, own, leaving, packed)
        if floor < lowest:
            lowest = floor
            seed = row
    best = np.inf
    best_tc = 0.0
    arg = -1
    for step in range(len(table) + 1):
        row = seed if step == 0 else step - 1
        if step > 0 and row == seed:
            continue
        u = table[row, 0]
        if u > best:
            break
        j = int(table[row, 1])
        p = int(table[row, 2])
        if p == a:
            tc = 0.0
        elif p < 0:
            tc = packed[0]
        else:
            if _entry_floor(table, row, a, own, leaving, packed) > best + SLACK * (abs(best) + 1.0):
                continue
            tc = _exact_tc(a, nodes[j], p, viseme, leaving, arriving, natural, len(natural), packed)
        cost = (0.0 + tc) + u
        if cost < best or (cost == best and j < arg):
            best = cost
            best_tc = tc
            arg = j
    return arg, best, best_tc


@njit(cache=True)
def entry_costs(
    a: int, nodes: np.ndarray, unary: np.ndarray, pre: np.ndarray, viseme: np.ndarray,
    leaving: np.ndarray, arriving: np.ndarray, natural: np.ndarray, packed: np.ndarray,
) -> np.ndarray:  # fmt: skip
    """(0 + TC(a, b)) + U(b) for every b of ``nodes`` (their U in ``unary``): the exact step
    from the one node ``a`` (``search._exact_kernel``) to the last bit, each pair read from
    two ``JoinRecords`` rows instead of six arrays."""
    f = np.empty(len(nodes))
    for j in range(len(nodes)):
        b = nodes[j]
        p = pre[b]
        if p == a:
            tc = 0.0
        elif p < 0:
            tc = packed[0]
        else:
            tc = _exact_tc(a, b, p, viseme, leaving, arriving, natural, len(natural), packed)
        f[j] = (0.0 + tc) + unary[j]
    return f


@njit(cache=True, inline="always")
def _given(
    b: int, root: int, position: np.ndarray, old_position: np.ndarray, old_back: np.ndarray,
    old_sure: np.ndarray, old_kind: np.ndarray, old_prev_nodes: np.ndarray,
    old_prev_root: np.ndarray,
) -> tuple[int, int]:  # fmt: skip
    """Node b's best predecessor in the last window (its position now, and its row there)
    when it won by the margin and descends from ``root``; else (−1, −1)."""
    o = old_position[b]
    if o < 0 or not old_sure[o] or old_kind[o] == UNCAPTURED:
        return -1, -1
    if old_prev_root[old_back[o]] != root:
        return -1, -1
    return position[old_prev_nodes[old_back[o]]], o


@njit(cache=True)
def lag_step(
    prev_nodes: np.ndarray, prev_f: np.ndarray, prev_root: np.ndarray, next_nodes: np.ndarray,
    next_u: np.ndarray, pre: np.ndarray, viseme: np.ndarray, leaving: np.ndarray,
    arriving: np.ndarray, dims: int, packed: np.ndarray, position: np.ndarray,
    old_position: np.ndarray, old_nodes: np.ndarray, old_back: np.ndarray,
    old_sure: np.ndarray, old_kind: np.ndarray, old_terms: np.ndarray,
    old_prev_nodes: np.ndarray, old_prev_root: np.ndarray, root: int,
) -> tuple[
    np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, int
]:  # fmt: skip
    """``fast_step`` (the same nodes, φ, order and predecessors, bit for bit), taking some
    best predecessors from the last window's step into the same layer (``old_*``, in its
    ascending φ; empty when there is none) instead of scanning: next_nodes[j]'s, when there
    it won by the margin (``old_sure``) and descended from ``root``, the node that window
    committed (``old_prev_root``: each predecessor's node in that window's first layer). The
    layer before must hold the nodes it held there. A given pair's cost is summed from its
    terms in ``_scan``'s order, so it is the value the scan computes.

    ``prev_root``: each of ``prev_nodes``' node in this window's first layer. ``position``
    and ``old_position`` (N) are scratch, all −1, and left so. Returns, in ascending φ:
    nodes, φ, predecessor positions, sure (a scanned node's best predecessor won by the
    margin; a given one keeps the flag), kinds (``PRICED``, ``NATURAL``, ``UNCAPTURED``),
    the best pair's cost terms (see ``_scan``) and roots; and the nodes scanned."""
    for i in range(len(prev_nodes)):
        position[prev_nodes[i]] = i
    for i in range(len(old_nodes)):
        old_position[old_nodes[i]] = i
    members, starts = _groups(prev_nodes, viseme)
    classes = len(starts) - 1
    n = len(next_nodes)
    f = np.empty(n)
    back = np.empty(n, dtype=np.int64)
    sure = np.ones(n, dtype=np.bool_)
    kind = np.full(n, PRICED, dtype=np.int8)
    terms = np.zeros((n, 4))
    scanned = 0
    for j in range(n):
        b = next_nodes[j]
        p = pre[b]
        if p < 0:
            f[j] = prev_f[0] + packed[0] + next_u[j]
            back[j] = 0
            kind[j] = UNCAPTURED
            continue
        i, o = _given(
            b, root, position, old_position, old_back, old_sure, old_kind, old_prev_nodes,
            old_prev_root,
        )  # fmt: skip
        if i >= 0:
            if old_kind[o] == NATURAL:
                best = prev_f[i]
            else:
                best = prev_f[i] + old_terms[o, 0] + old_terms[o, 1]
                if old_terms[o, 2] != 0.0:
                    best += old_terms[o, 2]
                best += old_terms[o, 3]
            f[j] = best + next_u[j]
            back[j] = i
            kind[j] = old_kind[o]
            for k in range(4):
                terms[j, k] = old_terms[o, k]
            continue
        scanned += 1
        best = np.inf
        arg = 0
        second = np.inf
        if position[p] >= 0:
            best = prev_f[position[p]]
            arg = position[p]
            kind[j] = NATURAL
        own = viseme[p]
        row = terms[j]
        start = arg
        if own < classes:
            best, arg, second = _scan(
                members, starts[own], starts[own + 1], 0.0, best, arg, second, row, b, p,
                prev_nodes, prev_f, viseme, leaving, arriving, dims, packed,
            )  # fmt: skip
        for v in range(classes):
            if v != own and starts[v + 1] > starts[v]:
                best, arg, second = _scan(
                    members, starts[v], starts[v + 1], packed[3], best, arg, second, row, b,
                    p, prev_nodes, prev_f, viseme, leaving, arriving, dims, packed,
                )  # fmt: skip
        if kind[j] == NATURAL and arg != start:
            kind[j] = PRICED
        f[j] = best + next_u[j]
        back[j] = arg
        sure[j] = second >= best + _margin(best)
    for i in range(len(prev_nodes)):
        position[prev_nodes[i]] = -1
    for i in range(len(old_nodes)):
        old_position[old_nodes[i]] = -1
    order = np.argsort(f, kind="mergesort")
    ordered_back = back[order]
    return (
        next_nodes[order], f[order], ordered_back, sure[order], kind[order], terms[order],
        prev_root[ordered_back], scanned,
    )  # fmt: skip
