"""The cheapest path through layers of candidates (min-plus dynamic programme), compiled.

Sketch: layer l holds sizes[l] nodes, node b costing nodes[l, b]; a join from node a of
layer l to node b of layer l + 1 costs edges[l, a, b]. The forward pass keeps, for every
node of the latest layer, the least cost of a path ending there:
fresh[b] = min_a (total[a] + edge[a, b]) + node[b] (``relax``), each node's best
predecessor kept as a back-pointer; the cheapest last node and the back-pointers give the
path (``trace``). The work is Σ_l sizes[l]·sizes[l + 1].

Ties: a node's predecessor is the first (lowest position) a of least total[a] + edge[a, b],
and the path ends at the first node of least total, so among paths of equal cost the
search returns, in exact arithmetic, the one whose positions read from the last layer back
are lowest. The sums are added in that order (path total + join, then + node), so a caller
that adds its own terms in that order gets its own results to the bit.

``forward`` searches a window first .. stop of a ``Trellis`` whose last layer may be priced
apart (``ending``: DAM's window prices its last phoneme with the next one unknown), and
``cheapest_path`` the whole trellis. ``first_min_plus`` is one node's step on a column of
join costs, for a caller that prices joins as it goes (expressive-dp's exact search, whose
N × N joins per layer are too many to hold).

Who uses it: DAM's mode search (``engines.dam.kernels.choose_modes``: a window per span,
over a trellis built once per call) and expressive-dp's exact search
(``engines.expressive_dp.search``, Alg. 1). The other layered searches differ, each for a
reason its module gives: anime-graph's (``engines.anime_graph.layered.cheapest``) runs over
the sparse edges its reachability pass recorded and breaks ties by node id, not position;
expressive-dp's fast step (``fast_step``) scans each layer pruned and sorted, with
cut-offs; the HMM trellis (``trellis``) is max-plus over log-probabilities, its streaming
decoder over each state's sparse predecessors.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit


class Trellis(NamedTuple):
    """Layers padded to one width W: ``nodes`` (L, W) each layer's node costs, ``sizes``
    (L,) int64 how many lead each row, ``edges`` (L − 1, W, W) the joins, edges[l, a, b] from
    node a of layer l to node b of layer l + 1."""

    nodes: np.ndarray
    sizes: np.ndarray
    edges: np.ndarray


class Survivors(NamedTuple):
    """A search's work arrays: ``total`` and ``fresh`` (W,) the path costs of two
    consecutive layers, ``backs`` (L, W) int64, backs[l, b] the position in layer l − 1 of
    node b's best predecessor."""

    total: np.ndarray
    fresh: np.ndarray
    backs: np.ndarray


def survivors(trellis: Trellis) -> Survivors:
    """Work arrays for searches of ``trellis``."""
    layers, width = trellis.nodes.shape
    return Survivors(np.empty(width), np.empty(width), np.zeros((layers, width), np.int64))


@njit(cache=True)
def first_min_plus(total: np.ndarray, column: np.ndarray, count: int) -> tuple[float, int]:
    """The least total[a] + column[a] over a < ``count`` (≥ 1) and its first position."""
    best = 0
    best_cost = total[0] + column[0]
    for a in range(1, count):
        cost = total[a] + column[a]
        if cost < best_cost:
            best, best_cost = a, cost
    return best_cost, best


@njit(cache=True)
def relax(
    total: np.ndarray,
    rows: int,
    edge: np.ndarray,
    node: np.ndarray,
    columns: int,
    fresh: np.ndarray,
    back: np.ndarray,
) -> None:
    """One layer's step: for b < ``columns``, fresh[b] = min over a < ``rows`` of
    (total[a] + edge[a, b]) + node[b], back[b] the first position of the minimum."""
    for b in range(columns):
        best = 0
        best_cost = total[0] + edge[0, b]
        for a in range(1, rows):
            cost = total[a] + edge[a, b]
            if cost < best_cost:
                best, best_cost = a, cost
        fresh[b] = best_cost + node[b]
        back[b] = best


@njit(cache=True)
def forward(trellis: Trellis, first: int, stop: int, ending: np.ndarray, work: Survivors) -> int:
    """The forward pass over layers ``first`` .. ``stop`` of ``trellis``, layer ``stop``'s
    node costs taken from ``ending`` instead of its row: fills work.backs[first + 1 ..
    stop] and returns the position of the first cheapest node of layer ``stop``."""
    nodes, sizes, edges = trellis.nodes, trellis.sizes, trellis.edges
    total, fresh = work.total, work.fresh
    start = ending if first == stop else nodes[first]
    for a in range(sizes[first]):
        total[a] = start[a]
    for j in range(first + 1, stop + 1):
        node = ending if j == stop else nodes[j]
        relax(total, sizes[j - 1], edges[j - 1], node, sizes[j], fresh, work.backs[j])
        total, fresh = fresh, total
    position = 0
    for a in range(1, sizes[stop]):
        if total[a] < total[position]:
            position = a
    return position


@njit(cache=True)
def trace(backs: np.ndarray, stop: int, until: int, position: int) -> int:
    """The position at layer ``until`` of the path through ``position`` at layer ``stop``."""
    for j in range(stop, until, -1):
        position = backs[j, position]
    return position


@njit(cache=True)
def cheapest_path(trellis: Trellis, work: Survivors) -> np.ndarray:
    """The position in each layer (L,) of the cheapest path through the whole ``trellis``."""
    stop = len(trellis.sizes) - 1
    path = np.empty(stop + 1, dtype=np.int64)
    path[stop] = forward(trellis, 0, stop, trellis.nodes[stop], work)
    for j in range(stop, 0, -1):
        path[j - 1] = work.backs[j, path[j]]
    return path
