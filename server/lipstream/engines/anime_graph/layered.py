"""Compiled kernels of the layered LongestMatching and its tie-break (numba).

Sketch: ``reach`` is the paper's degree-bounded depth-first search from every
start node at once, run breadth first: layer d holds the nodes that end a
path spelling Q_i..Q_i+d, and the next layer follows the out-edges of its
nodes into nodes carrying Q_i+d+1. Every (node, depth) state is stored once
and every edge stepped along is recorded, so the run's length is the number
of layers. ``cheapest`` marks the survivors (states from which the last layer
is reachable) by one backward sweep over the recorded edges, prices only
those (audio distance to the nearest member with the label, or the pose
discontinuity of each join), relaxes the edges layer by layer and backtracks:
dynamic programming over the run's trellis, exactly the cheapest of the
longest paths. Ties go to the lowest predecessor id, then to the lowest last
node id. A query costs O(states + edges stepped), whatever the graph's size.

Why not the shared layered search (``numerics.layered``): that one runs over dense
layers, every node of a layer joined to every node of the next, and breaks ties by
position. Here a layer's states join only along the graph edges ``reach`` recorded
(a dense trellis would price mostly absent joins), only the survivors are priced at
all, and ties go to the lowest node id, which is not the order of states in a
layer, so the relaxation walks the recorded edges instead.

Arrays, CSR keyed by node * n_labels + label: ``step_offsets`` over
``step_targets``, the successors of the node that carry the label (so a
step touches only edges it keeps), and ``NodeMembers``: ``entry_offsets`` over
``entry_members``, the node's member animes with the label, and ``motion`` (n,),
the anime each node shows.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from .costs import TileRanking, audio_cost, pose_jump


class NodeMembers(NamedTuple):
    """A graph's members by (node, label), built once per ``LayeredMatcher``: node c's
    member animes with label l are entry_members[entry_offsets[key] : entry_offsets[key +
    1]], key = c * ``n_labels`` + l; ``motion`` (n,) int64 is the anime each node shows."""

    n_labels: int
    entry_offsets: np.ndarray
    entry_members: np.ndarray
    motion: np.ndarray


class Layers(NamedTuple):
    """What ``reach`` found: ``states`` (N,) node ids layer after layer, ``layer_offsets``
    (depth + 1,), and the edges stepped as (``sources``, ``targets``) state pairs (M,),
    grouped by layer."""

    states: np.ndarray
    layer_offsets: np.ndarray
    sources: np.ndarray
    targets: np.ndarray


_CACHE = True


@njit(cache=_CACHE)
def _grow(values: np.ndarray, needed: int) -> np.ndarray:
    if needed <= len(values):
        return values
    grown = np.empty(max(needed, 2 * len(values)), dtype=values.dtype)
    grown[: len(values)] = values
    return grown


@njit(cache=_CACHE)
def reach(
    query: np.ndarray,
    cap: int,
    first: np.ndarray,
    n_labels: int,
    step_offsets: np.ndarray,
    step_targets: np.ndarray,
    slot: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Layers of the run of ``query`` (L,) labels (``cap`` <= 0: uncapped) seeded with the
    nodes ``first``. ``slot`` (n,) int64 scratch, all -1, is left all -1.

    Returns states (N,) node ids layer after layer, layer_offsets (depth + 1,), and the
    edges stepped (M,) as (source state, target state), grouped by layer."""
    states = np.empty(max(16, 4 * len(first)), dtype=np.int64)
    states[: len(first)] = first
    layer_offsets = np.empty(len(query) + 1, dtype=np.int64)
    layer_offsets[0], layer_offsets[1] = 0, len(first)
    sources = np.empty(64, dtype=np.int64)
    targets = np.empty(64, dtype=np.int64)
    n_states, n_edges, depth = len(first), 0, 1
    while depth < len(query) and (cap <= 0 or depth < cap):
        label = query[depth]
        if label < 0 or label >= n_labels:
            break  # no phoneme: the tables are not indexed with it
        low, high = layer_offsets[depth - 1], layer_offsets[depth]
        bound = 0
        for state in range(low, high):
            key = states[state] * n_labels + label
            bound += step_offsets[key + 1] - step_offsets[key]
        states = _grow(states, n_states + bound)
        sources = _grow(sources, n_edges + bound)
        targets = _grow(targets, n_edges + bound)
        for state in range(low, high):
            key = states[state] * n_labels + label
            for step in range(step_offsets[key], step_offsets[key + 1]):
                target = step_targets[step]
                if slot[target] < 0:
                    states[n_states] = target
                    slot[target] = n_states
                    n_states += 1
                sources[n_edges], targets[n_edges] = state, slot[target]
                n_edges += 1
        for state in range(high, n_states):
            slot[states[state]] = -1
        if n_states == high:
            break
        depth += 1
        layer_offsets[depth] = n_states
    return states[:n_states], layer_offsets[: depth + 1], sources[:n_edges], targets[:n_edges]


@njit(cache=_CACHE)
def cheapest(
    query: np.ndarray,
    layers: Layers,
    previous: int,
    ranking: TileRanking,
    members: NodeMembers,
) -> np.ndarray:
    """Node ids (L,) of the cheapest path through the ``layers`` ``reach`` found.

    With ``ranking.use_audio``, state s at depth d costs the audio distance to
    query_summaries[d] (L, D) and joins are free; otherwise states are free and each
    join (and the one from ``previous``, when >= 0) costs its pose discontinuity."""
    states, layer_offsets = layers.states, layers.layer_offsets
    sources, targets = layers.sources, layers.targets
    use_audio, poses, motion = ranking.use_audio, ranking.poses, members.motion
    last, first, successor = poses.last, poses.first, poses.successor
    n_layers = len(layer_offsets) - 1
    alive = np.zeros(len(states), dtype=np.bool_)
    alive[layer_offsets[n_layers - 1] :] = True
    for edge in range(len(sources) - 1, -1, -1):
        if alive[targets[edge]]:
            alive[sources[edge]] = True
    costs = np.full(len(states), math.inf)
    back = np.full(len(states), -1, dtype=np.int64)
    depth_end = layer_offsets[1]
    for state in range(depth_end):
        if alive[state]:
            costs[state] = _node_cost(state, 0, query, states, ranking, members)
            if previous >= 0 and not use_audio:
                costs[state] += pose_jump(
                    motion[previous], motion[states[state]], last, first, successor
                )
    depth = 1
    edge = 0
    while edge < len(sources):
        while targets[edge] >= layer_offsets[depth + 1]:
            _price_layer(depth, layers, alive, costs, query, ranking, members)
            depth += 1
        target, source = targets[edge], sources[edge]
        if alive[target]:
            join = (
                0.0
                if use_audio
                else pose_jump(
                    motion[states[source]], motion[states[target]], last, first, successor
                )
            )
            reaching = costs[source] + join
            held = back[target]
            if (
                held < 0
                or reaching < costs[target]
                or (reaching == costs[target] and states[source] < states[held])
            ):
                costs[target], back[target] = reaching, source
        edge += 1
    while depth < n_layers:
        _price_layer(depth, layers, alive, costs, query, ranking, members)
        depth += 1
    best = layer_offsets[n_layers - 1]
    for state in range(best + 1, layer_offsets[n_layers]):
        if costs[state] < costs[best] or (
            costs[state] == costs[best] and states[state] < states[best]
        ):
            best = state
    path = np.empty(n_layers, dtype=np.int64)
    for depth in range(n_layers - 1, -1, -1):
        path[depth] = states[best]
        best = back[best]
    return path


@njit(cache=_CACHE)
def _node_cost(
    state: int,
    depth: int,
    query: np.ndarray,
    states: np.ndarray,
    ranking: TileRanking,
    members: NodeMembers,
) -> float:
    if not ranking.use_audio:
        return 0.0
    return audio_cost(
        states[state],
        query[depth],
        ranking.query_summaries[depth],
        members.n_labels,
        members.entry_offsets,
        members.entry_members,
        ranking.summaries,
    )


@njit(cache=_CACHE)
def _price_layer(
    depth: int,
    layers: Layers,
    alive: np.ndarray,
    costs: np.ndarray,
    query: np.ndarray,
    ranking: TileRanking,
    members: NodeMembers,
) -> None:
    """Add the node costs of layer ``depth``, once all its incoming edges are relaxed."""
    layer_offsets = layers.layer_offsets
    for state in range(layer_offsets[depth], layer_offsets[depth + 1]):
        if alive[state]:
            costs[state] += _node_cost(state, depth, query, layers.states, ranking, members)
