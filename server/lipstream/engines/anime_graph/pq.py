"""PQ-Matching(h, h_q) (Alg. 1): exact branch and bound in windows, the paper's baseline.

Sketch: the query is cut into windows Q_i..Q_i+h-1. In each window PQ-DFS
finds the node sequence minimizing (jumps, tie-break cost) exactly: a
depth-first branch and bound whose children are taken from a priority queue
ordered by (jumps so far, cost so far); a greedy dive gives the first
incumbent, and a branch is cut as soon as (jumps, cost + a lower bound on
the cost still to come) cannot beat it. Since siblings come in priority
order, the first sibling that cannot beat the incumbent ends its level.
A window's jumps include the join to the last node already committed. The
first h_q nodes are committed and the window advances by h_q. Partial paths
are never merged, so the work grows exponentially with h, as in the paper;
memory stays O(h * candidates). A caller's ``check`` (the request's
``WorkGuard`` and ``pq_budget_s``) runs before each window and every
``CHECK_EVERY`` partial paths, and stops the search by raising.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ...errors import LipstreamError
from .costs import Labels, Ranking
from .graph import SearchGraph

_TOLERANCE = 1e-9
CHECK_EVERY = 256
SEARCH_TIMEOUT = "search_timeout"

Check = Callable[[], None]


class SearchTimeout(LipstreamError):
    """PQ-Matching used up the request's ``pq_budget_s``."""

    code = SEARCH_TIMEOUT


def _unchecked() -> None:
    return None


@dataclass(frozen=True)
class WindowResult:
    """The optimal ``nodes`` of one window, their ``jumps`` and ``cost``; ``expanded``
    counts the partial paths extended."""

    nodes: np.ndarray
    jumps: int
    cost: float
    expanded: int


@dataclass
class _Level:
    """The children of one partial path, in priority order, and the next one to try."""

    nodes: np.ndarray
    jumps: np.ndarray
    costs: np.ndarray
    cursor: int = 0
    order: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))


def _children(
    graph: SearchGraph,
    ranking: Ranking,
    last: int | None,
    candidates: np.ndarray,
    costs: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """(extra jumps, extra cost) of appending each candidate after node ``last``."""
    if last is None:
        return np.zeros(len(candidates), dtype=np.int64), costs
    before = np.full(len(candidates), last)
    jumps = (~graph.is_edge(before, candidates)).astype(np.int64)
    return jumps, costs + ranking.join_costs(before, candidates)


def _better(jumps: int, cost: float, best_jumps: int, best_cost: float) -> bool:
    return jumps < best_jumps or (jumps == best_jumps and cost < best_cost - _TOLERANCE)


def _dive(
    graph: SearchGraph,
    ranking: Ranking,
    candidates: list[np.ndarray],
    costs: list[np.ndarray],
    anchor: int | None,
) -> tuple[list[int], int, float]:
    """A quick complete path: follow an edge when one exists, else the cheapest node."""
    path: list[int] = []
    jumps, cost, last = 0, 0.0, anchor
    for nodes, node_costs in zip(candidates, costs):
        extra_jumps, extra_cost = _children(graph, ranking, last, nodes, node_costs)
        pick = int(np.lexsort((extra_cost, extra_jumps))[0])
        path.append(int(nodes[pick]))
        jumps, cost, last = jumps + int(extra_jumps[pick]), cost + float(extra_cost[pick]), path[-1]
    return path, jumps, cost


def pq_window(
    graph: SearchGraph,
    ranking: Ranking,
    query: Labels,
    start: int,
    stop: int,
    anchor: int | None = None,
    check: Check = _unchecked,
) -> WindowResult:
    """PQ-DFS over ``query[start:stop]`` after the committed node ``anchor``; ``check`` runs
    first and every ``CHECK_EVERY`` partial paths, and stops the search by raising."""
    check()
    positions = range(start, stop)
    candidates = [graph.nodes_with_label(int(query[p])) for p in positions]
    costs = [ranking.label_costs(p, int(query[p])) for p in positions]
    floor = np.zeros(len(costs) + 1)
    for depth in range(len(costs) - 1, -1, -1):
        floor[depth] = floor[depth + 1] + (float(costs[depth].min()) if len(costs[depth]) else 0.0)
    best_path, best_jumps, best_cost = _dive(graph, ranking, candidates, costs, anchor)

    def level(depth: int, last: int | None, jumps: int, cost: float) -> _Level:
        extra_jumps, extra_cost = _children(graph, ranking, last, candidates[depth], costs[depth])
        child = _Level(candidates[depth], jumps + extra_jumps, cost + extra_cost)
        child.order = np.lexsort((np.arange(len(child.nodes)), child.costs, child.jumps))
        return child

    stack = [level(0, anchor, 0, 0.0)]
    path: list[int] = []
    expanded = 0
    while stack:
        depth = len(stack) - 1
        current = stack[-1]
        if current.cursor == len(current.order):
            stack.pop()
            continue
        index = int(current.order[current.cursor])
        current.cursor += 1
        jumps, cost = int(current.jumps[index]), float(current.costs[index])
        if not _better(jumps, cost + floor[depth + 1], best_jumps, best_cost):
            current.cursor = len(current.order)
            continue
        del path[depth:]
        path.append(int(current.nodes[index]))
        if depth + 1 == len(candidates):
            best_path, best_jumps, best_cost = list(path), jumps, cost
            continue
        expanded += 1
        if expanded % CHECK_EVERY == 0:
            check()
        stack.append(level(depth + 1, path[-1], jumps, cost))
    return WindowResult(np.asarray(best_path, dtype=np.int64), best_jumps, best_cost, expanded)


def pq_matching(
    graph: SearchGraph,
    ranking: Ranking,
    query: Labels,
    window: int,
    advance: int,
    anchor: int | None = None,
    check: Check = _unchecked,
) -> tuple[np.ndarray, int]:
    """PQ-Matching(h=window, h_q=advance) over the whole query: (nodes, partial paths
    expanded). ``check`` as for ``pq_window``."""
    nodes: list[int] = []
    expanded = 0
    position = 0
    while position < len(query):
        stop = min(len(query), position + window)
        result = pq_window(graph, ranking, query, position, stop, anchor, check)
        expanded += result.expanded
        keep = len(result.nodes) if stop == len(query) else min(advance, len(result.nodes))
        nodes.extend(int(node) for node in result.nodes[:keep])
        anchor = nodes[-1]
        position += keep
    return np.asarray(nodes, dtype=np.int64), expanded
