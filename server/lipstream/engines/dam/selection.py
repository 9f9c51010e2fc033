"""Mode selection (Lin et al., Eq. 10): an exact search over the layered mode graph.

Layers are the phonemes of a window, nodes the candidate modes of each phoneme.
The cost of a path is E = w_c·E_c + w_s·E_s:

- E_c (node cost): the negative log-likelihood of the mode given its previous and
  next phoneme and the span's emotion, each from the training context counts with
  additive (Laplace) smoothing ``alpha`` over the phoneme's candidate modes, so a
  context never seen costs the same for every mode instead of infinity. A
  neighbour outside the window (not yet known) contributes nothing.
- E_s (edge cost): the C2 discontinuity at the join of consecutive animemes: the
  squared jumps of value, slope and curvature between A_a at local time 1 and A_b
  at 0, derivatives converted to real time and scaled by a reference phoneme
  duration so the three terms share units.

A dynamic programme over the layers (Viterbi in min-plus form) finds the same
optimum as A* on this graph; ties go to the lower mode index.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .dominance import derivative_powers


@dataclass(frozen=True)
class Layer:
    """One phoneme of the window: candidate mode indices, duration (s), neighbour phonemes
    (-1: unknown) and emotion index (-1: none)."""

    candidates: np.ndarray
    duration: float
    previous: int
    following: int
    emotion: int


@dataclass(frozen=True)
class Costs:
    """Context counts and the animemes' end derivatives, read by the search."""

    previous: np.ndarray
    following: np.ndarray
    emotion: np.ndarray
    starts: np.ndarray  # (modes, 3, channels): A, A', A'' at local time 0
    ends: np.ndarray  # (modes, 3, channels): at local time 1
    reference_duration: float
    alpha: float
    w_context: float
    w_smooth: float


def end_derivatives(coefficients: np.ndarray, at: float) -> np.ndarray:
    """(modes, 3, channels): the value, first and second local-time derivative at ``at``."""
    degree = coefficients.shape[1] - 1
    rows = np.stack([derivative_powers(at, degree, order) for order in range(3)])
    return np.asarray(np.einsum("om,kmc->koc", rows, coefficients))


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
