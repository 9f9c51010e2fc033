"""The fixed-lag search window after window: each window reuses its predecessor's steps.

Method. A fixed-lag call searches the window of layers s .. e from the node c committed
at s − 1 (``search.search``'s fast search over one segment) and commits the node o_s of
its cheapest path. The next call searches s + 1 .. e + 1 from c' = o_s: both ends moved,
so the whole window used to be searched again. Yet of its layers only e + 1 is new, and
on the others most of the work of the last window stands:

* φ' (this window's forward costs) and φ (the last window's) obey φ'(a) ≥ φ(a) − φ(c')
  for every node a of layers s + 1 .. e, with equality when the last window's best path
  into a runs through c' at layer s ("a descends from c'", followed through the
  predecessor positions): a path from c' to a, led by the last window's way into c',
  is a path of the last window.
* So when a node b's best predecessor a* in the last window descends from c' and beat
  every other predecessor by the margin ``fast_step.SURE`` (the step scans past the best
  by that margin to know), a* is still b's best predecessor, every other one is dearer
  by almost the margin (sums of 1e-15 relative rounding cannot close it), and the step
  takes it without a scan; b's φ' is summed from a*'s φ' and the pair's cost terms as the
  scan sums it, so it is the value the scan would find, bit for bit.
* Every other node is scanned (``fast_step.lag_step``: ``fast_step``'s scan, the bar
  raised by the margin); the first layer is priced from c' as before (every node's
  exact TC, ``fast_step.entry_costs``), and Rule 4 nodes take the cheapest φ' as before.

Every layer thus holds the nodes, φ, order and predecessors ``search`` finds for the
window, so the path, its ties and the committed node are the same. The paths into a
layer merge within a few layers, so most nodes of the later layers descend from the
committed node: a call scans the new layer e + 1, the nodes layer e gains as it stops
being the last (a last layer has no TC out of it, so its pruning bound is tighter), and
the nodes whose best way in ran through another node than c'. A window of two layers
has nothing to reuse and goes to ``search``; a window that is not its predecessor
moved on by one layer (the first of a segment, one after a one-layer commit) is
searched afresh by the same step. The nodes priced (``SearchResult.candidates``) are
those of the first layer and those scanned.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from .fast_step import Ranked
from .search import LayerSpec, SearchResult, SearchSpace, _candidates


class PassLayer(NamedTuple):
    """One layer of a window's search: its ``candidates`` (node order, as
    ``search._candidates`` gives them) and the layer ``ranked`` (``fast_step.Ranked``)."""

    candidates: np.ndarray
    ranked: Ranked


class LagMemory:
    """A stream's last fixed-lag window: its first layer's index and its layers."""

    def __init__(self, size: int) -> None:
        self.size = size
        self.start = -1
        self.layers: list[PassLayer] = []

    def search(
        self,
        space: SearchSpace,
        layers: Sequence[LayerSpec],
        excluded: np.ndarray,
        start: int,
        before: int,
        guard: object | None = None,
    ) -> SearchResult:
        """``search.search(space, layers, excluded, before=before)`` for ``layers`` (two or
        more, none silent), the spans from index ``start`` on: the same path; the nodes
        priced are those whose way in was searched."""
        old = self.layers if self.start == start - 1 and before >= 0 else []
        position, old_position = _scratch(self.size)
        calls, joins = space.calls, space.joins
        candidates = _candidates(space, layers, excluded, 0, before >= 0, True, 0)
        f = candidates.costs
        if before >= 0:
            f = calls.entry_costs(before, candidates, joins)
        order = np.argsort(f, kind="stable")
        first = candidates.nodes[order]
        empty = _EMPTY  # the first layer's nodes have no predecessor in the window
        ranked = Ranked(first, f[order], empty.back, empty.sure, empty.kind, empty.terms, first)
        passed = [PassLayer(candidates.nodes, ranked)]
        priced = len(first)
        aligned = True
        for index in range(1, len(layers)):
            if guard is not None:
                guard.check()  # type: ignore[attr-defined]
            previous = passed[-1]
            candidates = _candidates(space, layers, excluded, index, True, True, 0)
            # the bound φ' ≥ φ − φ(c') holds when every layer before held the same nodes
            aligned = (
                aligned and index < len(old) and _same(old[index].candidates, previous.candidates)
            )
            known, then = (
                (old[index + 1].ranked, old[index].ranked)
                if aligned and index + 1 < len(old)
                else (_EMPTY, _EMPTY)
            )
            ranked, scanned = calls.lag_step(
                previous.ranked, candidates, joins, known, then, before, position, old_position
            )
            passed.append(PassLayer(candidates.nodes, ranked))
            priced += scanned
        self.start, self.layers = start, passed
        last = passed[-1].ranked
        position_in_layer = int(np.argmin(last.costs))
        cost = float(last.costs[position_in_layer])
        path = np.empty(len(layers), dtype=np.int64)
        for index in range(len(layers) - 1, 0, -1):
            path[index] = passed[index].ranked.nodes[position_in_layer]
            position_in_layer = int(passed[index].ranked.back[position_in_layer])
        path[0] = first[position_in_layer]
        return SearchResult(path, cost, priced)


def _empty_layer() -> Ranked:
    none = np.zeros(0, dtype=np.int64)
    no_terms = np.zeros((0, 4))
    return Ranked(
        none, np.zeros(0), none, np.zeros(0, dtype=bool), np.zeros(0, dtype=np.int8), no_terms, none
    )


_EMPTY = _empty_layer()
"""No layer: the last window's, when it has none to give."""


_local = threading.local()


def _scratch(size: int) -> tuple[np.ndarray, np.ndarray]:
    """Two (``size``,) position arrays, all −1, of this thread: ``lag_step`` leaves them so,
    and a thread runs one step at a time, so its streams share them."""
    kept: dict[int, tuple[np.ndarray, np.ndarray]] = _local.__dict__.setdefault("scratch", {})
    pair = kept.get(size)
    if pair is None:
        pair = kept[size] = (np.full(size, -1, dtype=np.int64), np.full(size, -1, dtype=np.int64))
    return pair


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return a is b or (len(a) == len(b) and bool(np.array_equal(a, b)))
