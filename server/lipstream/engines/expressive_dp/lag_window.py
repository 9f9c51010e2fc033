"""One fixed-lag window searched in one compiled call: ``fast_step.lag_step`` layer after layer.

Method. ``lag_search`` keeps a stream's last window and hands the next one's candidates to
``lag_window``: the first layer priced from the committed node (``fast_step.entry_costs``)
and ranked, each further layer stepped by ``lag_step`` with the last window's same layer
(when every layer before held the same nodes), and the cheapest path followed back, all in
one call. The layers travel stacked in flat arrays with row offsets (``Stacked``,
``Window``, whose ``ranked`` holds every layer's ``Ranked`` rows), so a call unboxes a few
arrays once instead of a ``Ranked`` per step, and the
window's Python bookkeeping (slicing, alignment checks, the walk back) runs compiled. Every
sum, sort and tie is ``lag_search``'s former per-step loop's, so the path and its cost are
the same to the last bit.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from .fast_step import Joins, Layer, Ranked, empty_ranked, entry_costs, lag_step, ranked_rows


class Stacked(NamedTuple):
    """A window's candidates, layer after layer: layer l's are ``nodes`` and their U
    (``costs``) at rows ``offsets[l]`` .. ``offsets[l + 1]``, node order as
    ``search._candidates`` gives them."""

    nodes: np.ndarray
    costs: np.ndarray
    offsets: np.ndarray


class Window(NamedTuple):
    """A window's search, its layers stacked at the rows ``offsets`` gives (as ``Stacked``):
    ``candidates`` (each layer's, node order) and ``ranked``, every layer ranked (ascending
    φ within a layer; the first layer's ``back``, ``sure``, ``kind`` and ``terms`` are
    zeros, never read)."""

    offsets: np.ndarray
    candidates: np.ndarray
    ranked: Ranked


class Scratch(NamedTuple):
    """Two (N,) position arrays, all −1, that ``lag_step`` leaves so."""

    position: np.ndarray
    old_position: np.ndarray


@njit(cache=True, inline="always")
def _ranked(window: Window, layer: int) -> Ranked:
    """Layer ``layer`` of ``window`` (views)."""
    return ranked_rows(window.ranked, window.offsets[layer], window.offsets[layer + 1])


@njit(cache=True, inline="always")
def _same_candidates(old: Window, old_layer: int, stacked: Stacked, layer: int) -> bool:
    low, high = old.offsets[old_layer], old.offsets[old_layer + 1]
    start, stop = stacked.offsets[layer], stacked.offsets[layer + 1]
    if high - low != stop - start:
        return False
    for k in range(high - low):
        if old.candidates[low + k] != stacked.nodes[start + k]:
            return False
    return True


@njit(cache=True, inline="always")
def _keep(window: Window, layer: int, ranked: Ranked) -> None:
    low, kept = window.offsets[layer], window.ranked
    for k in range(len(ranked.nodes)):
        kept.nodes[low + k] = ranked.nodes[k]
        kept.costs[low + k] = ranked.costs[k]
        kept.root[low + k] = ranked.root[k]
        if layer > 0:
            kept.back[low + k] = ranked.back[k]
            kept.sure[low + k] = ranked.sure[k]
            kept.kind[low + k] = ranked.kind[k]
            for t in range(4):
                kept.terms[low + k, t] = ranked.terms[k, t]


@njit(cache=True)
def lag_window(
    stacked: Stacked, old: Window, joins: Joins, before: int, scratch: Scratch
) -> tuple[Window, np.ndarray, float, int]:
    """The window of ``stacked``'s layers from ``before`` (−1: none), each step
    ``fast_step.lag_step`` given the last window's layers (``old``; no layers: none to
    reuse): the window (for the next call), its cheapest path, that path's φ and the nodes
    priced (the first layer's and those scanned)."""
    count = len(stacked.offsets) - 1
    total = stacked.offsets[count]
    window = Window(stacked.offsets, stacked.nodes, empty_ranked(total))
    low, high = stacked.offsets[0], stacked.offsets[1]
    first = Layer(stacked.nodes[low:high], stacked.costs[low:high])
    f = entry_costs(before, first, joins) if before >= 0 else first.costs.copy()
    order = np.argsort(f, kind="mergesort")
    nodes = first.nodes[order]
    empty = empty_ranked(0)
    previous = Ranked(nodes, f[order], empty.back, empty.sure, empty.kind, empty.terms, nodes)
    _keep(window, 0, previous)
    priced = high - low
    old_count = len(old.offsets) - 1
    none = ranked_rows(old.ranked if old_count > 0 else window.ranked, 0, 0)
    aligned = True
    for index in range(1, count):
        # the bound φ' ≥ φ − φ(c') holds when every layer before held the same nodes
        aligned = aligned and index < old_count and _same_candidates(old, index, stacked, index - 1)
        known, then = none, none
        if aligned and index + 1 < old_count:
            known, then = _ranked(old, index + 1), _ranked(old, index)
        low, high = stacked.offsets[index], stacked.offsets[index + 1]
        candidates = Layer(stacked.nodes[low:high], stacked.costs[low:high])
        previous, scanned = lag_step(
            previous, candidates, joins, known, then, before, scratch.position, scratch.old_position
        )
        _keep(window, index, previous)
        priced += scanned
    position = int(np.argmin(previous.costs))
    cost = previous.costs[position]
    path = np.empty(count, dtype=np.int64)
    for index in range(count - 1, -1, -1):
        row = stacked.offsets[index] + position
        path[index] = window.ranked.nodes[row]
        position = window.ranked.back[row]
    return window, path, cost, priced
