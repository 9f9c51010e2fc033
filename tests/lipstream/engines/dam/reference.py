"""The mode search written plainly in numpy, the oracle the compiled search is tested against.

Sketch: ``select_mode`` runs the exact search of ``selection`` (``cheapest_path`` over E_c and
E_s) over the window of spans k - search_behind .. k + ahead and takes its choice at k;
``ModeMemo`` keeps the layers and costs that one call's overlapping windows share;
``path_cost`` sums E of one path term by term, for enumerating every path.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from lipstream.engines.base import SynthesisRequest
from lipstream.engines.dam import DamModel
from lipstream.engines.dam.selection import (
    Costs,
    Layer,
    cheapest_path,
    context_cost,
    smooth_cost,
)
from lipstream.timeline import PhonemeSpan


class ModeMemo:
    """Layers, E_c and E_s of one synthesis call, shared by its overlapping search windows.

    A layer depends on its span, its neighbours and whether the next span lies beyond the
    window (``cut``): then the next phoneme counts as unknown."""

    def __init__(
        self, model: DamModel, spans: Sequence[PhonemeSpan], request: SynthesisRequest
    ) -> None:
        self.model = model
        self.spans = spans
        self.request = request
        self.layers: dict[tuple[int, bool], Layer] = {}
        self.nodes: dict[tuple[int, bool], np.ndarray] = {}
        self.edges: dict[int, np.ndarray] = {}

    def layer(self, index: int, cut: bool) -> Layer:
        key = (index, cut)
        if key not in self.layers:
            last = index if cut else index + 1
            self.layers[key] = self.model.layer(self.spans, index, last, self.request)
        return self.layers[key]

    def node(self, index: int, cut: bool) -> np.ndarray:
        key = (index, cut)
        if key not in self.nodes:
            self.nodes[key] = context_cost(self.model.costs, self.layer(index, cut))
        return self.nodes[key]

    def edge(self, index: int) -> np.ndarray:
        """E_s between span ``index`` and the next (candidates do not depend on the window)."""
        if index not in self.edges:
            self.edges[index] = smooth_cost(
                self.model.costs, self.layer(index, False), self.layer(index + 1, False)
            )
        return self.edges[index]


def select_mode(
    model: DamModel,
    spans: Sequence[PhonemeSpan],
    index: int,
    ahead: int,
    request: SynthesisRequest,
    memo: ModeMemo | None = None,
) -> int:
    """The mode of span ``index``: the exact search over spans index - search_behind ..
    index + ``ahead`` (those that exist), its choice at ``index``. ``memo`` keeps the
    layers and costs of one call's overlapping windows."""
    memo = ModeMemo(model, spans, request) if memo is None else memo
    first = max(0, index - model.search_behind)
    last = index + ahead
    indices = range(first, min(last, len(spans) - 1) + 1)
    nodes = [memo.node(k, k + 1 > last) for k in indices]
    edges = [memo.edge(k) for k in indices[:-1]]
    path = cheapest_path(model.costs, nodes, edges)
    return int(memo.layer(index, False).candidates[path[index - first]])


def path_cost(costs: Costs, layers: Sequence[Layer], path: Sequence[int]) -> float:
    """E of one path (candidate positions), summed term by term."""
    total = 0.0
    for index, layer in enumerate(layers):
        total += costs.w_context * float(context_cost(costs, layer)[path[index]])
        if index:
            joins = smooth_cost(costs, layers[index - 1], layer)
            total += costs.w_smooth * float(joins[path[index - 1], path[index]])
    return total
