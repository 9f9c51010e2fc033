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

``sliding_positions`` searches a window around each layer k of a range of one ``Trellis``,
k − behind .. k + ahead, and keeps the window's choice at k; a window that ends before
the trellis does prices its last layer apart (DAM prices a window's last phoneme with the
next one unknown). Every window runs in one call: with a call per window, DAM's mode
search over 400 spans cost a tenth more. With behind and ahead ≥ L every window is the
whole trellis and the positions are its cheapest path.

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


@njit(cache=True)
def sliding_positions(
    trellis: Trellis,
    endings: np.ndarray,
    low: int,
    high: int,
    behind: int,
    ahead: int,
    work: Survivors,
) -> np.ndarray:
    """For each layer k of ``low`` .. ``high``, the position at k of the cheapest path over
    the window max(0, k − ``behind``) .. min(k + ``ahead``, L − 1): the forward pass over
    its layers (each node's step ``first_min_plus``'s, written out), then the first
    cheapest node of its last layer traced back to k. A window that ends before the
    trellis does (k + ahead < L) prices its last layer by its row of ``endings`` (L, W)
    instead. work.backs is scratch. One call runs every window, so a window costs no call.
    """
    nodes, sizes, edges = trellis.nodes, trellis.sizes, trellis.edges
    total, fresh, backs = work.total, work.fresh, work.backs
    layers = len(sizes)
    positions = np.empty(max(high - low + 1, 0), dtype=np.int64)
    for until in range(low, high + 1):
        first, stop = max(0, until - behind), min(until + ahead, layers - 1)
        ending = endings[stop] if stop == until + ahead else nodes[stop]
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
        positions[until - low] = position
    return positions
