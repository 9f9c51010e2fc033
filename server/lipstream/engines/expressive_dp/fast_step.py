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

Why not the shared layered search (``numerics.layered``, which the exact search
``search._exact_kernel`` steps with): that one prices every pair of a layer and its
predecessor, in position order. This step never prices most pairs: it needs the
previous layer sorted by φ and grouped by viseme to stop each scan early, joins priced
term by term against the best so far, and Rules 1 and 4 taken without a scan, so its
loop is its own; what it keeps of the shared one is the answer, the exact step's
optimum.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import NamedTuple

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


class Joins(NamedTuple):
    """What pricing a join TC(a, b) reads, over the N nodes: ``pre`` (N,) each node's
    captured predecessor (−1: none), ``viseme`` (N,) its viseme, ``leaving`` and
    ``arriving`` (``JoinRecords``' rows), ``natural`` (K,) the records' column of each
    velocity coordinate, ``packed`` the weights (``costs.Weights.packed``). Built once per
    search space (``search.SearchSpace.joins``)."""

    pre: np.ndarray
    viseme: np.ndarray
    leaving: np.ndarray
    arriving: np.ndarray
    natural: np.ndarray
    packed: np.ndarray


class Layer(NamedTuple):
    """A layer's ``nodes`` (k,) and their ``costs`` (k,): φ, ascending, for a layer searched;
    U for the candidates of the next one."""

    nodes: np.ndarray
    costs: np.ndarray


class Ranked(NamedTuple):
    """A layer of a fixed-lag window's search (``lag_step``), in ascending φ: ``nodes``,
    ``costs`` (φ), ``back`` (each one's best predecessor's position in the layer before),
    ``sure`` (it won by the margin), ``kind`` (``PRICED``, ``NATURAL``, ``UNCAPTURED``),
    ``terms`` (k, 4) the best pair's cost terms (see ``_scan``) and ``root`` (each one's
    node in the window's first layer). The first layer's ``back``, ``sure``, ``kind`` and
    ``terms`` are empty."""

    nodes: np.ndarray
    costs: np.ndarray
    back: np.ndarray
    sure: np.ndarray
    kind: np.ndarray
    terms: np.ndarray
    root: np.ndarray


@njit(cache=True, inline="always")
def ranked_rows(ranked: Ranked, low: int, high: int) -> Ranked:
    """Rows ``low`` .. ``high`` of every field of ``ranked`` (views)."""
    return Ranked(
        ranked.nodes[low:high],
        ranked.costs[low:high],
        ranked.back[low:high],
        ranked.sure[low:high],
        ranked.kind[low:high],
        ranked.terms[low:high],
        ranked.root[low:high],
    )


@njit(cache=True)
def empty_ranked(size: int) -> Ranked:
    """A ``Ranked`` of ``size`` rows, all zeros (``empty_ranked.py_func`` outside compiled
    code)."""
    return Ranked(
        np.zeros(size, dtype=np.int64),
        np.zeros(size),
        np.zeros(size, dtype=np.int64),
        np.zeros(size, dtype=np.bool_),
        np.zeros(size, dtype=np.int8),
        np.zeros((size, 4)),
        np.zeros(size, dtype=np.int64),
    )


class Best(NamedTuple):
    """A scan's best so far: its ``cost``, its position ``arg`` in the layer before, and the
    least other cost seen (``second``)."""

    cost: float
    arg: int
    second: float


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
    previous: Layer | Ranked,
    joins: Joins,
    members: np.ndarray,
    group: tuple[int, int],
    penalty: float,
    b: int,
    p: int,
    best: Best,
    terms: np.ndarray,
) -> Best:
    """One viseme group of ``previous`` (``members[group[0]:group[1]]``, ascending φ), every
    pair into b (p = pre(b)) adding ``penalty``, priced up to a bar of the best +
    ``_margin``: the same pairs replace the best, in the same order, as with the bar at the
    best, and ``second`` (the least other cost seen) is exact below the bar, so the best
    wins by the margin iff ``second`` ≥ the bar at the end. The best pair's terms of the
    cost, (α3·PGap, VGap, PNT or 0, α2·DSC), go to ``terms``."""
    prev_nodes, prev_f = previous.nodes, previous.costs
    viseme, leaving, arriving, packed = joins.viseme, joins.leaving, joins.arriving, joins.packed
    dims = joins.natural.shape[0]
    cost_best, arg, second = best.cost, best.arg, best.second
    bar = cost_best + _margin(cost_best)
    for k in range(group[0], group[1]):
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
        if cost < cost_best:
            second = min(second, cost_best)
            cost_best = cost
            arg = i
            bar = cost_best + _margin(cost_best)
            terms[0] = gaps
            terms[1] = speed
            terms[2] = packed[3] if penalised else 0.0
            terms[3] = smooth
        elif cost < second:
            second = cost
    return Best(cost_best, arg, second)


@njit(cache=True, inline="always")
def _scan_all(
    previous: Layer | Ranked,
    joins: Joins,
    members: np.ndarray,
    starts: np.ndarray,
    b: int,
    p: int,
    best: Best,
    terms: np.ndarray,
) -> Best:
    """``_scan`` over the group of p's viseme first, then every other group (with PNT)."""
    own = joins.viseme[p]
    classes = len(starts) - 1
    if own < classes:
        best = _scan(
            previous, joins, members, (starts[own], starts[own + 1]), 0.0, b, p, best, terms
        )
    penalty = joins.packed[3]
    for v in range(classes):
        if v != own and starts[v + 1] > starts[v]:
            group = (starts[v], starts[v + 1])
            best = _scan(previous, joins, members, group, penalty, b, p, best, terms)
    return best


@njit(cache=True)
def fast_step(
    previous: Layer, candidates: Layer, joins: Joins, position: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``candidates``' nodes in ascending φ, their φ, and the position of each one's best
    predecessor in ``previous`` (φ ascending); ``position`` (N) is scratch, all -1, and
    left so."""
    prev_nodes, prev_f = previous.nodes, previous.costs
    next_nodes, next_u = candidates.nodes, candidates.costs
    for i in range(len(prev_nodes)):
        position[prev_nodes[i]] = i
    members, starts = _groups(prev_nodes, joins.viseme)
    f = np.empty(len(next_nodes))
    back = np.empty(len(next_nodes), dtype=np.int64)
    terms = np.empty(4)  # the best pair's terms, which this step does not keep
    for j in range(len(next_nodes)):
        b = next_nodes[j]
        p = joins.pre[b]
        if p < 0:
            f[j] = prev_f[0] + joins.packed[0] + next_u[j]
            back[j] = 0
            continue
        best = Best(np.inf, 0, np.inf)
        if position[p] >= 0:
            best = Best(prev_f[position[p]], position[p], np.inf)
        best = _scan_all(previous, joins, members, starts, b, p, best, terms)
        f[j] = best.cost + next_u[j]
        back[j] = best.arg
    for i in range(len(prev_nodes)):
        position[prev_nodes[i]] = -1
    order = np.argsort(f, kind="mergesort")
    return next_nodes[order], f[order], back[order]


ENTRY_VELOCITY = 4
"""Leading velocity coordinates (descending variance) an entry table holds per candidate."""


def entry_table(candidates: Layer, joins: Joins) -> np.ndarray:
    """Per candidate of a layer (their U in ``costs``), what ``best_entry`` reads for every
    one of them, contiguous, in ascending U (then position): [U, its position in
    ``candidates.nodes``, pre(b), viseme of pre(b) (−1 without one), the first
    ``ENTRY_VELOCITY`` coordinates of its first velocity in ``JoinRecords``' order]."""
    nodes, unary = candidates
    order = np.argsort(unary, kind="stable")
    chosen = nodes[order]
    before = joins.pre[chosen]
    kept = min(ENTRY_VELOCITY, len(joins.natural))
    table = np.empty((len(nodes), 4 + kept))
    table[:, 0] = unary[order]
    table[:, 1] = order
    table[:, 2] = before
    table[:, 3] = np.where(before >= 0, joins.viseme[np.maximum(before, 0)], -1)
    table[:, 4:] = joins.arriving[chosen, :kept]
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
def _exact_tc(a: int, b: int, p: int, joins: Joins) -> float:
    """``costs.transition_cost(a, b)`` for p = pre(b) ≥ 0, p ≠ a, from ``JoinRecords``' rows:
    every sum in ``transition_cost``'s order (velocity coordinates read at ``natural``, the
    records' column of each coordinate), so the same value to the last bit."""
    leaving, arriving, natural, packed = joins.leaving, joins.arriving, joins.natural, joins.packed
    dims = natural.shape[0]
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
    if joins.viseme[a] != joins.viseme[p]:
        cost += packed[3]
    return float(cost + packed[1] * _dsc(leaving, a, arriving, b, dims))


@njit(cache=True)
def best_entry(
    a: int, nodes: np.ndarray, table: np.ndarray, joins: Joins
) -> tuple[int, float, float]:
    """The position j in ``nodes`` (``table`` = their ``entry_table``) of the least
    (0 + TC(a, b)) + U(b), b = nodes[j], the lowest j among equal costs, that cost and its
    TC: the exact step from the one node ``a`` (``search._exact_kernel``) and its argmin.

    The table runs in ascending U. A first pass prices first the pair of least floor
    (``_entry_floor``) among those of U below the least floor so far (the pair of Rule 1,
    b = suc(a), has floor U(b) and its cost); the second stops at the first U above the
    best (TC ≥ 0), drops a pair whose floor exceeds the best (with ``SLACK``, as in
    ``_scan``) and prices the rest exactly (``_exact_tc``)."""
    leaving, packed = joins.leaving, joins.packed
    own = joins.viseme[a]
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
            tc = _exact_tc(a, nodes[j], p, joins)
        cost = (0.0 + tc) + u
        if cost < best or (cost == best and j < arg):
            best = cost
            best_tc = tc
            arg = j
    return arg, best, best_tc


@njit(cache=True)
def entry_costs(a: int, candidates: Layer, joins: Joins) -> np.ndarray:
    """(0 + TC(a, b)) + U(b) for every b of ``candidates`` (their U in ``costs``): the exact
    step from the one node ``a`` (``search._exact_kernel``) to the last bit, each pair read
    from two ``JoinRecords`` rows instead of six arrays."""
    nodes, unary = candidates.nodes, candidates.costs
    f = np.empty(len(nodes))
    for j in range(len(nodes)):
        b = nodes[j]
        p = joins.pre[b]
        if p == a:
            tc = 0.0
        elif p < 0:
            tc = joins.packed[0]
        else:
            tc = _exact_tc(a, b, p, joins)
        f[j] = (0.0 + tc) + unary[j]
    return f


@njit(cache=True, inline="always")
def _given(
    b: int, root: int, position: np.ndarray, old_position: np.ndarray, known: Ranked, then: Ranked
) -> tuple[int, int]:
    """Node b's best predecessor in the last window (its position now, and its row in
    ``known``) when it won by the margin and descends from ``root``; else (−1, −1)."""
    o = old_position[b]
    if o < 0 or not known.sure[o] or known.kind[o] == UNCAPTURED:
        return -1, -1
    if then.root[known.back[o]] != root:
        return -1, -1
    return position[then.nodes[known.back[o]]], o


@njit(cache=True)
def lag_step(
    previous: Ranked,
    candidates: Layer,
    joins: Joins,
    known: Ranked,
    then: Ranked,
    root: int,
    position: np.ndarray,
    old_position: np.ndarray,
) -> tuple[Ranked, int]:
    """``fast_step`` (the same nodes, φ, order and predecessors, bit for bit), taking some
    best predecessors from the last window's step into the same layer (``known``, in its
    ascending φ; empty when there is none) instead of scanning: a candidate's, when there
    it won by the margin (``known.sure``) and descended from ``root``, the node that window
    committed (through ``then``, that window's layer before ``known``, whose ``root`` is
    each node's node in that window's first layer). The layer before (``previous``) must
    hold the nodes it held there. A given pair's cost is summed from its terms in
    ``_scan``'s order, so it is the value the scan computes.

    ``position`` and ``old_position`` (N) are scratch, all −1, and left so. Returns the
    layer ranked (a scanned node is ``sure`` when its best predecessor won by the margin;
    a given one keeps the flag) and the number of nodes scanned."""
    prev_nodes, prev_f = previous.nodes, previous.costs
    next_nodes, next_u = candidates.nodes, candidates.costs
    for i in range(len(prev_nodes)):
        position[prev_nodes[i]] = i
    for i in range(len(known.nodes)):
        old_position[known.nodes[i]] = i
    members, starts = _groups(prev_nodes, joins.viseme)
    n = len(next_nodes)
    f = np.empty(n)
    back = np.empty(n, dtype=np.int64)
    sure = np.ones(n, dtype=np.bool_)
    kind = np.full(n, PRICED, dtype=np.int8)
    terms = np.zeros((n, 4))
    scanned = 0
    for j in range(n):
        b = next_nodes[j]
        p = joins.pre[b]
        if p < 0:
            f[j] = prev_f[0] + joins.packed[0] + next_u[j]
            back[j] = 0
            kind[j] = UNCAPTURED
            continue
        i, o = _given(b, root, position, old_position, known, then)
        if i >= 0:
            old_terms = known.terms
            if known.kind[o] == NATURAL:
                cost = prev_f[i]
            else:
                cost = prev_f[i] + old_terms[o, 0] + old_terms[o, 1]
                if old_terms[o, 2] != 0.0:
                    cost += old_terms[o, 2]
                cost += old_terms[o, 3]
            f[j] = cost + next_u[j]
            back[j] = i
            kind[j] = known.kind[o]
            for k in range(4):
                terms[j, k] = old_terms[o, k]
            continue
        scanned += 1
        best = Best(np.inf, 0, np.inf)
        if position[p] >= 0:
            best = Best(prev_f[position[p]], position[p], np.inf)
            kind[j] = NATURAL
        start = best.arg
        best = _scan_all(previous, joins, members, starts, b, p, best, terms[j])
        if kind[j] == NATURAL and best.arg != start:
            kind[j] = PRICED
        f[j] = best.cost + next_u[j]
        back[j] = best.arg
        sure[j] = best.second >= best.cost + _margin(best.cost)
    for i in range(len(prev_nodes)):
        position[prev_nodes[i]] = -1
    for i in range(len(known.nodes)):
        old_position[known.nodes[i]] = -1
    order = np.argsort(f, kind="mergesort")
    ordered_back = back[order]
    ranked = Ranked(
        next_nodes[order],
        f[order],
        ordered_back,
        sure[order],
        kind[order],
        terms[order],
        previous.root[ordered_back],
    )
    return ranked, scanned
