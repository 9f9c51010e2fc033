"""The mode search written plainly in numpy, the oracle the compiled search is tested against.

Sketch: ``context_cost`` (E_c) and ``smooth_cost`` (E_s) price a layer's candidates and the
joins between two layers as ``selection`` defines them; ``cheapest_path`` is the min-plus
programme over them (first minimum on ties, as ``numerics.layered``), ``best_path`` the
same from the layers. ``select_mode`` runs it over the window of spans
k - search_behind .. k + ahead and takes its choice at k; ``ModeMemo`` keeps the layers
and costs that one call's overlapping windows share; ``path_cost`` sums E of one path term
by term, for enumerating every path.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from lipstream.engines.base import SynthesisRequest
from lipstream.engines.dam import DamModel
from lipstream.engines.dam.selection import Costs, Layer
from lipstream.timeline import PhonemeSpan


def _log_share(table: np.ndarray, candidates: np.ndarray, context: int, alpha: float) -> np.ndarray:
    counts = table[candidates, context].astype(np.float64) + alpha
    return np.asarray(np.log(counts / counts.sum()))


def context_cost(costs: Costs, layer: Layer) -> np.ndarray:
    """E_c of each candidate of ``layer``."""
    total = np.zeros(len(layer.candidates))
    for table, context in (
        (costs.previous, layer.previous),
        (costs.following, layer.following),
        (costs.emotion, layer.emotion),
    ):
        if context >= 0:
            total -= _log_share(table, layer.candidates, context, costs.alpha)
    return total


def smooth_cost(costs: Costs, left: Layer, right: Layer) -> np.ndarray:
    """E_s of each (left candidate, right candidate) join."""
    scale = np.array([1.0, costs.reference_duration, costs.reference_duration**2])
    left_end = costs.ends[left.candidates] * (scale / left.duration ** np.arange(3))[:, None]
    right_start = costs.starts[right.candidates] * (scale / right.duration ** np.arange(3))[:, None]
    jump = left_end[:, None] - right_start[None, :]
    return np.asarray(np.sum(jump * jump, axis=(2, 3)))


def best_path(costs: Costs, layers: Sequence[Layer]) -> np.ndarray:
    """The candidate position chosen in each layer, minimizing w_c·E_c + w_s·E_s."""
    nodes = [context_cost(costs, layer) for layer in layers]
    edges = [smooth_cost(costs, a, b) for a, b in zip(layers, layers[1:], strict=False)]
    return cheapest_path(costs, nodes, edges)


def cheapest_path(
    costs: Costs, nodes: Sequence[np.ndarray], edges: Sequence[np.ndarray]
) -> np.ndarray:
    """The min-plus programme over E_c of each layer's nodes and E_s of each join."""
    total = costs.w_context * nodes[0]
    back: list[np.ndarray] = []
    for node, edge in zip(nodes[1:], edges, strict=True):
        step = total[:, None] + costs.w_smooth * edge
        choice = np.argmin(step, axis=0)
        back.append(choice)
        total = step[choice, np.arange(step.shape[1])] + costs.w_context * node
    path = [int(np.argmin(total))]
    for choice in reversed(back):
        path.append(int(choice[path[-1]]))
    return np.asarray(path[::-1], dtype=np.int64)


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


def led_by_hand(spans: list[PhonemeSpan], lead: float) -> list[PhonemeSpan]:
    """Each /p b m/ after another span started ``lead`` earlier and that span ended there, by
    at most half that span (as moved already): the articulatory spans a model with
    ``bilabial_lead_s`` = ``lead`` renders, written out loop by loop."""
    led = list(spans)
    for k in range(1, len(led)):
        if led[k].phoneme in ("P", "B", "M") and lead > 0:
            shift = min(lead, (led[k - 1].end - led[k - 1].start) / 2)
            led[k - 1] = dataclasses.replace(led[k - 1], end=led[k - 1].end - shift)
            led[k] = dataclasses.replace(led[k], start=led[k].start - shift)
    return led
