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

Here a window's candidates are gathered (``search._candidates``, cached per layer) and
stacked; the entry, every step and the walk back run in one compiled call
(``lag_window``), which also keeps the window for the next call.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence

import numpy as np

from .fast_step import empty_ranked
from .lag_window import Scratch, Stacked, Window
from .search import LayerSpec, SearchResult, SearchSpace, _candidates


class LagMemory:
    """A stream's last fixed-lag window: its first layer's index and its layers
    (``lag_window.Window``)."""

    def __init__(self, size: int) -> None:
        self.size = size
        self.start = -1
        self.window = _NO_WINDOW

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
        priced are those whose way in was searched. ``guard`` is checked once, before the
        window's one compiled call."""
        if guard is not None:
            guard.check()  # type: ignore[attr-defined]
        old = self.window if self.start == start - 1 and before >= 0 else _NO_WINDOW
        parts = [
            _candidates(space, layers, excluded, index, index > 0 or before >= 0, True, 0)
            for index in range(len(layers))
        ]
        total, ends = 0, [0]
        for part in parts:
            total += len(part.nodes)
            ends.append(total)
        offsets = np.array(ends, dtype=np.int64)
        stacked = Stacked(
            np.concatenate([part.nodes for part in parts]),
            np.concatenate([part.costs for part in parts]),
            offsets,
        )
        scratch = _scratch(self.size)
        window, path, cost, priced = space.calls.lag_window(
            stacked, old, space.joins, before, scratch
        )
        self.start, self.window = start, window
        return SearchResult(path, float(cost), int(priced))


def _no_window() -> Window:
    return Window(np.zeros(1, dtype=np.int64), np.zeros(0, dtype=np.int64), empty_ranked.py_func(0))


_NO_WINDOW = _no_window()
"""No window: a stream's first, or one whose last window is not the one before."""


_local = threading.local()


def _scratch(size: int) -> Scratch:
    """The scratch of this thread for ``size`` nodes: ``lag_step`` leaves it all −1, and a
    thread runs one step at a time, so its streams share it."""
    kept: dict[int, Scratch] = _local.__dict__.setdefault("scratch", {})
    pair = kept.get(size)
    if pair is None:
        pair = kept[size] = Scratch(
            np.full(size, -1, dtype=np.int64), np.full(size, -1, dtype=np.int64)
        )
    return pair
