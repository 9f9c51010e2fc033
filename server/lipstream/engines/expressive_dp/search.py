"""The motion-node search: exact Viterbi DP (Alg. 1) and a fast search with the same optimum.

Method. Each layer i (an input phoneme) admits the nodes that are not
contaminated, or only its constrained node (B of Eq. 10), with unary cost
U_i(o) = OC + EMP. Alg. 1 computes φ_i(b) = U_i(b) + min_a [φ_{i−1}(a) + TC(a, b)]
over every pair, Θ(N²·T) (``search`` with ``fast=False``): each node's step is the
shared layered search's (``numerics.layered.first_min_plus``, first minimum on ties)
over the column of TC(a, b) priced for it, since the N × N joins of a layer are too
many to hold as a matrix. The fast search (``fast=True``) reaches the same
minimum with three exact reductions, and so keeps its own step (``fast_step``):

1. Dominance pruning, before any transition is priced: with b* the admitted
   node of least U_i(b*) + into[b*] + out_of[b*] (``costs.NodeBounds``; only
   the sides the layer has), any path through a node b with
   U_i(b) > U_i(b*) + into[b*] + out_of[b*] costs more than the same path through
   b*, so b is never on an optimal path and is dropped. Nodes of other phonemes
   or emotions go this way as soon as their OC/EMP exceed the bounds.
2. Rule-1 and Rule-4 transitions priced without a scan: a node without a
   captured predecessor costs α1·PNT from every a, so its best a is the cheapest
   φ; a node whose predecessor is admitted starts from φ(pre) + 0.
3. A sorted scan with cut-offs (``fast_step``, compiled): the previous layer's
   nodes grouped by viseme, each group in ascending φ; the scan of a group stops at
   the first a with φ(a) (+ PNT, when the group's viseme is not pre(b)'s) ≥ the
   best so far, since the rest of TC ≥ 0; a pair is dropped as soon as a partial
   sum of its velocity gap reaches the best, and its position gap and DSC are
   priced only when it still beats it. Each node's join features are one
   contiguous row per side (``fast_step.JoinRecords``, made at first use).

4. One layer after a fixed node (``one_layer``: each call of the causal rungs) needs only
   the argmin of TC(before, b) + U(b): ``fast_step.best_entry`` scans the layer's
   candidates in ascending U (``entry_table``, cached with the layer) and prices exactly,
   with the exact step's sums, only the pairs whose floor (U, PNT, a partial velocity
   gap) does not exceed the best: the exact step's node and ties, bit for bit.

The nodes dominance pruning (1.) keeps depend only on the layer's phoneme, emotion and sides,
so they are cached (``SearchSpace.survivors``) with b*; contaminated nodes are
dropped from the cached set, which stays exact unless b* itself is contaminated
(then the layer is pruned afresh).

``before`` is a node fixed ahead of the first layer (the fixed-lag search's last
committed node); its TC into the first layer counts. A stream's successive fixed-lag
windows are searched by ``lag_search``, which finds this search's nodes, φ and order in
every layer while reusing the last window's steps. Ties may pick different
paths of equal cost; the cost is the same.

Silence splits the search, as /pau/ splits the paper's sentences. A silence
layer's OC is 0 for every node, so dominance pruning keeps thousands of its
nodes and their pairs were most of the fast search's work; yet the node chosen
there is never shown: post-processing draws a silence as a straight line from
the last frame of the node before it to the first frame of the node after it.
So a silence layer gets no node (``NO_NODE`` in the path) and no cost, and the
layers between silences are independent segments: no TC across a silence (the
node after one starts a segment as the first layer of a search does; ``before``
reaches only a segment that starts the layers). The optimum is the sum of the
segments' optima, in exact DP and in the fast search alike; the out-of bound of
pruning is dropped at a segment's last layer, as at the last layer of a search.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import NamedTuple

import numpy as np
from numba import njit

from ...errors import InvalidRequestError
from ...numerics.direct_call import DirectCall
from ...numerics.layered import first_min_plus
from .costs import NodeBounds, TableOne, transition_cost, unary_costs
from .fast_step import (
    JoinRecords,
    Joins,
    Layer,
    best_entry,
    entry_costs,
    entry_table,
    fast_step,
)
from .lag_window import lag_window
from .nodes import SILENCE_INDEX, NodeDatabase, NodeFeatures

INF = np.inf
NO_NODE = -1
"""The path's entry at a silence layer."""


@dataclass(frozen=True)
class LayerSpec:
    """One input phoneme: its phoneme and emotion index, and its constrained node (-1)."""

    phoneme: int
    emotion: int
    constrained: int = -1

    @property
    def silent(self) -> bool:
        return self.phoneme == SILENCE_INDEX


class SpaceCalls(NamedTuple):
    """A search space's compiled steps, each called through a ``DirectCall`` of its own:
    the arguments a space hands them keep one type per step."""

    best_entry: DirectCall
    entry_costs: DirectCall
    fast_step: DirectCall
    lag_window: DirectCall
    transition_cost: DirectCall


@dataclass(frozen=True)
class SearchSpace:
    """A database with its features, bounds and packed weights (``costs.Weights.packed``)."""

    nodes: NodeDatabase
    features: NodeFeatures
    bounds: NodeBounds
    packed: np.ndarray
    observed: dict[tuple[int, int], np.ndarray] = field(default_factory=dict, compare=False)
    """OC + EMP per (phoneme, emotion), filled on first use."""
    survivors: dict[tuple[int, int, bool, bool], tuple[np.ndarray, int, np.ndarray]] = field(
        default_factory=dict, compare=False
    )
    """The nodes dominance pruning keeps with nothing contaminated, the node b* that set
    the threshold, and the kept nodes' OC + EMP, per (phoneme, emotion, has a layer before,
    has a layer after)."""
    entries: dict[tuple[int, int, bool, bool], np.ndarray] = field(
        default_factory=dict, compare=False
    )
    """``fast_step.entry_table`` of the survivors of a layer with a node before it."""

    @cached_property
    def no_exclusion(self) -> np.ndarray:
        """An exclusion mask with nothing excluded, known so without reading it."""
        mask = np.zeros(self.nodes.size, dtype=bool)
        mask.setflags(write=False)
        return mask

    @cached_property
    def records(self) -> JoinRecords:
        """Each node's join features in one row per side, for the fast step (at first use)."""
        return JoinRecords.of(self.nodes, self.features)

    @cached_property
    def calls(self) -> SpaceCalls:
        return SpaceCalls(
            DirectCall(best_entry),
            DirectCall(entry_costs),
            DirectCall(fast_step),
            DirectCall(lag_window),
            DirectCall(transition_cost),
        )

    @cached_property
    def joins(self) -> Joins:
        """What the fast step prices a join from (at first use)."""
        records = self.records
        viseme = self.features.viseme
        return Joins(
            self.nodes.pre, viseme, records.leaving, records.arriving, records.natural, self.packed
        )

    @cached_property
    def table_one(self) -> TableOne:
        """What Table I's TC reads, for the exact search and ``tc``."""
        f = self.features
        return TableOne(
            self.nodes.pre,
            f.viseme,
            f.first_position,
            f.last_position,
            f.first_velocity,
            f.last_velocity,
            f.leaving,
            f.arriving,
            self.packed,
        )

    def observation(self, layer: LayerSpec) -> np.ndarray:
        """OC + EMP of every node for ``layer`` (read-only)."""
        key = (layer.phoneme, layer.emotion)
        cost = self.observed.get(key)
        if cost is None:  # a race only computes the same read-only array twice
            viseme = self.features.viseme
            cost = unary_costs(self.nodes, viseme, layer.phoneme, layer.emotion, self.packed)
            cost.setflags(write=False)
            self.observed[key] = cost
        return cost

    def unary(self, layer: LayerSpec, excluded: np.ndarray) -> np.ndarray:
        """U(o) for every node, infinite where the node is not admitted."""
        cost = self.observation(layer)
        if layer.constrained >= 0:
            only = np.full(len(cost), INF)
            only[layer.constrained] = cost[layer.constrained]
            return only
        return np.where(excluded, INF, cost)

    def unary_at(self, layer: LayerSpec, excluded: np.ndarray, node: int) -> float:
        """``unary(layer, excluded)[node]``, without the other nodes'."""
        if node != layer.constrained and (layer.constrained >= 0 or excluded[node]):
            return INF
        return float(self.observation(layer)[node])

    def tc(self, a: int, b: int) -> float:
        return float(self.calls.transition_cost(a, b, self.table_one))


@dataclass(frozen=True)
class SearchResult:
    path: np.ndarray
    cost: float
    candidates: int
    """Nodes priced over every layer (after pruning, for the fast search)."""


@njit(cache=True)
def _exact_kernel(
    previous: Layer, candidates: Layer, table: TableOne
) -> tuple[np.ndarray, np.ndarray]:
    prev_nodes, prev_f = previous.nodes, previous.costs
    next_nodes, next_u = candidates.nodes, candidates.costs
    f = np.empty(len(next_nodes))
    back = np.empty(len(next_nodes), dtype=np.int64)
    column = np.empty(len(prev_nodes))
    for j in range(len(next_nodes)):
        b = next_nodes[j]
        for i in range(len(prev_nodes)):
            column[i] = transition_cost(prev_nodes[i], b, table)
        best, arg = first_min_plus(prev_f, column, len(prev_nodes))
        f[j] = best + next_u[j]
        back[j] = arg
    return f, back


def _exact_step(
    space: SearchSpace, previous: Layer, candidates: Layer
) -> tuple[np.ndarray, np.ndarray]:
    return _exact_kernel(previous, candidates, space.table_one)


def _best_entry(
    space: SearchSpace, before: int, candidates: Layer, table: np.ndarray | None = None
) -> tuple[int, float, float]:
    if table is None:
        table = entry_table(candidates, space.joins)
    return space.calls.best_entry(before, candidates.nodes, table, space.joins)  # type: ignore[no-any-return]


def _candidates(
    space: SearchSpace,
    layers: Sequence[LayerSpec],
    excluded: np.ndarray,
    index: int,
    has_before: bool,
    fast: bool,
    offset: int,
) -> Layer:
    layer = layers[index]
    sides = (index > 0 or has_before, index + 1 < len(layers))
    if fast and layer.constrained < 0:
        kept, threshold, kept_unary = _survivors(space, layer, *sides)
        if excluded is space.no_exclusion or not excluded.any():
            return Layer(kept, kept_unary)
        if not excluded[threshold]:  # the threshold stands: drop only contaminated survivors
            return _read_only(kept[~excluded[kept]], space.observation(layer))
    unary = space.unary(layer, excluded)
    admitted = np.isfinite(unary)
    if not admitted.any():
        raise InvalidRequestError(
            f"phoneme {offset + index} of the search admits no node: every node is contaminated",
            where="contamination",
        )
    if fast:
        admitted &= unary <= _pruning_scores(space, unary, *sides)[admitted].min()
    return _read_only(np.flatnonzero(admitted), unary)


def _pruning_scores(space: SearchSpace, unary: np.ndarray, into: bool, out: bool) -> np.ndarray:
    """U + the bounds of the sides the layer has: b* is the node of least score."""
    score = unary.copy()
    if into:
        score += space.bounds.into
    if out:
        score += space.bounds.out_of
    return score


def _survivors(
    space: SearchSpace, layer: LayerSpec, into: bool, out: bool
) -> tuple[np.ndarray, int, np.ndarray]:
    key = (layer.phoneme, layer.emotion, into, out)
    kept = space.survivors.get(key)
    if kept is None:  # a race only computes the same read-only arrays twice
        unary = space.observation(layer)
        score = _pruning_scores(space, unary, into, out)
        best = int(np.argmin(score))
        nodes, kept_unary = _read_only(np.flatnonzero(unary <= score[best]), unary)
        kept = (nodes, best, kept_unary)
        space.survivors[key] = kept
    return kept


def _read_only(nodes: np.ndarray, unary: np.ndarray) -> Layer:
    """A layer's nodes and their U (of ``unary``, every node's), frozen: cached layers are
    shared, and the kernels are compiled for one kind of array."""
    kept_unary = unary[nodes]
    nodes.setflags(write=False)
    kept_unary.setflags(write=False)
    return Layer(nodes, kept_unary)


def search(
    space: SearchSpace,
    layers: Sequence[LayerSpec],
    excluded: np.ndarray,
    *,
    fast: bool = True,
    before: int = -1,
    guard: object | None = None,
) -> SearchResult:
    """The cheapest path over ``layers`` (node ids, ``NO_NODE`` at silences) and its cost;
    ``excluded`` (N,) marks contaminated nodes; ``fast`` selects the pruned search, else
    Alg. 1 over every pair. Each run of layers between silences is searched on its own."""
    path = np.full(len(layers), NO_NODE, dtype=np.int64)
    cost, priced = 0.0, 0
    for start, stop in segments(layers):
        found = _segment(
            space, layers[start:stop], excluded, fast, before if start == 0 else -1, guard, start
        )
        path[start:stop] = found.path
        cost += found.cost
        priced += found.candidates
    return SearchResult(path, cost, priced)


def one_layer(
    space: SearchSpace, layer: LayerSpec, excluded: np.ndarray, before: int = -1
) -> tuple[int, int, float]:
    """``search`` over the one non-silent ``layer`` (fast): its node, the nodes priced, and
    TC(``before``, node) (0 without ``before``), without the segment bookkeeping."""
    candidates = _candidates(space, (layer,), excluded, 0, before >= 0, True, 0)
    nodes, unary = candidates
    if before < 0:
        return int(nodes[int(np.argmin(unary))]), len(nodes), 0.0
    key = (layer.phoneme, layer.emotion, True, False)
    survivors = space.survivors.get(key)
    shared = survivors is not None and nodes is survivors[0]  # not narrowed by contamination
    table = space.entries.get(key) if shared else None
    if table is None:
        table = entry_table(candidates, space.joins)
        if shared:
            space.entries[key] = table
    position, _, tc = _best_entry(space, before, candidates, table)
    return int(nodes[position]), len(nodes), tc


def segments(layers: Sequence[LayerSpec]) -> list[tuple[int, int]]:
    """The [start, stop) runs of non-silent layers."""
    runs: list[tuple[int, int]] = []
    start = 0
    for index, layer in enumerate([*layers, None]):
        if layer is None or layer.silent:
            if index > start:
                runs.append((start, index))
            start = index + 1
    return runs


def _segment(
    space: SearchSpace,
    layers: Sequence[LayerSpec],
    excluded: np.ndarray,
    fast: bool,
    before: int,
    guard: object | None,
    offset: int,
) -> SearchResult:
    """Viterbi over ``layers`` (none silent; the first is layer ``offset`` of the search)."""
    backs: list[np.ndarray] = []
    members: list[np.ndarray] = []
    first = _candidates(space, layers, excluded, 0, before >= 0, fast, offset)
    nodes, f = first
    if fast and before >= 0 and len(layers) == 1:
        position, cost, _ = _best_entry(space, before, first)
        return SearchResult(nodes[position : position + 1], cost, len(nodes))
    if before >= 0 and fast:
        f = space.calls.entry_costs(before, first, space.joins)
    elif before >= 0:
        start = Layer(np.array([before], dtype=np.int64), np.zeros(1))
        f, _ = _exact_step(space, start, first)
    priced = len(nodes)
    if fast:
        order = np.argsort(f, kind="stable")
        nodes, f = nodes[order], f[order]
        scratch = np.full(space.nodes.size, -1, dtype=np.int64)
    members.append(nodes)
    for index in range(1, len(layers)):
        if guard is not None:
            guard.check()  # type: ignore[attr-defined]
        candidates = _candidates(space, layers, excluded, index, True, fast, offset)
        next_nodes = candidates.nodes
        priced += len(next_nodes)
        if fast:
            next_nodes, f, back = space.calls.fast_step(
                Layer(nodes, f), candidates, space.joins, scratch
            )
        else:
            f, back = _exact_step(space, Layer(nodes, f), candidates)
        backs.append(back)
        members.append(next_nodes)
        nodes = next_nodes
    position = int(np.argmin(f))
    cost = float(f[position])
    path = np.empty(len(layers), dtype=np.int64)
    for index in range(len(layers) - 1, -1, -1):
        path[index] = members[index][position]
        if index > 0:
            position = int(backs[index - 1][position])
    return SearchResult(path, cost, priced)
