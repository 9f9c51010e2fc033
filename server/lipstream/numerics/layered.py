"""The cheapest path through layers of candidates (min-plus dynamic programme), compiled.

Sketch: layer l holds sizes[l] nodes, node b costing nodes[l, b]; a join from node a of
layer l to node b of layer l + 1 costs edges[l, a, b]. The forward pass keeps, for every
node of the latest layer, the least cost of a path ending there:
fresh[b] = min_a (total[a] + edge[a, b]) + node[b], each node's best predecessor kept as
a back-pointer; the cheapest last node and the back-pointers give the path. The work is
Σ_l sizes[l]·sizes[l + 1].

Ties: a node's predecessor is the first (lowest position) a of least total[a] + edge[a, b],
and the path ends at the first node of least total, so among paths of equal cost the
search returns, in exact arithmetic, the one whose positions read from the last layer back
are lowest. The sums are added in that order (path total + join, then + node), so a caller
that adds its own terms in that order gets its own results to the bit.

``window_positions`` searches windows first .. stop of one ``Trellis`` (``Windows``), a
window's last layer priced apart when asked (DAM's window prices its last phoneme with
the next one unknown), all in one call: called once per window, the search cost about a
tenth more in DAM's calls. ``cheapest_path`` is the window of the whole trellis.
``first_min_plus`` is one node's step on a column of join costs, for a caller that prices
joins as it goes (expressive-dp's exact search, whose N × N joins per layer are too many
to hold).

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


class Windows(NamedTuple):
    """Searches over parts of one trellis, one per row: layers ``first`` .. ``stop``, the
    position wanted at layer ``until`` (first ≤ until ≤ stop), and ``apart``: whether layer
    ``stop``'s node costs are read from its row of the endings instead (int64 arrays, bool
    ``apart``)."""

    first: np.ndarray
    stop: np.ndarray
    until: np.ndarray
    apart: np.ndarray


@njit(cache=True)
def window_positions(
    trellis: Trellis, endings: np.ndarray, windows: Windows, work: Survivors
) -> np.ndarray:
    """For each window, the position at layer ``until`` of its cheapest path: the forward
    pass over its layers (each node's step ``first_min_plus``'s, written out), then the
    first cheapest node of its last layer traced back. ``endings`` (L, W) holds the node
    costs a window's last layer may be priced by apart; work.backs is scratch. One call
    runs every window, so a window costs no call."""
    nodes, sizes, edges = trellis.nodes, trellis.sizes, trellis.edges
    total, fresh, backs = work.total, work.fresh, work.backs
    positions = np.empty(len(windows.first), dtype=np.int64)
    for w in range(len(windows.first)):
        first, stop, until = windows.first[w], windows.stop[w], windows.until[w]
        ending = endings[stop] if windows.apart[w] else nodes[stop]
        start = ending if first == stop else nodes[first]
        for a in range(sizes[first]):
            total[a] = start[a]
        for j in range(first + 1, stop + 1):
            node = ending if j == stop else nodes[j]
            edge = edges[j - 1]
            for b in range(sizes[j]):
                best = 0
                best_cost = total[0] + edge[0, b]
                for a in range(1, sizes[j - 1]):
                    cost = total[a] + edge[a, b]
                    if cost < best_cost:
                        best, best_cost = a, cost
                fresh[b] = best_cost + node[b]
                backs[j, b] = best
            total[: sizes[j]] = fresh[: sizes[j]]
        position = 0
        for a in range(1, sizes[stop]):
            if total[a] < total[position]:
                position = a
        for j in range(stop, until, -1):
            position = backs[j, position]
        positions[w] = position
    return positions


def cheapest_path(trellis: Trellis) -> np.ndarray:
    """The position in each layer (L,) of the cheapest path through the whole ``trellis``:
    the window of all its layers, its position wanted at each."""
    layers = len(trellis.sizes)
    every = np.arange(layers, dtype=np.int64)
    whole = Windows(np.zeros(layers, np.int64), np.full(layers, layers - 1), every, every < 0)
    return np.asarray(window_positions(trellis, trellis.nodes, whole, survivors(trellis)))
