"""The costs of Deng & Neumann (Eq. 4–10, Tables I–II), and bounds on them for pruning.

Method. A path o_1..o_T over input phonemes P_i with emotion modifiers E_i costs
Σ TC(o_i, o_{i+1}) + Σ [OC(P_i, o_i) + EMP(E_i, o_i) + B(i, o_i)].

* TC (Table I, first rule that applies): 0 when pre(o_{i+1}) = o_i; α1·PNT when
  o_{i+1} has no captured predecessor; otherwise α2·DSC(o_i, pre(o_{i+1})) + PVC,
  plus PNT when viseme(o_i) differs from viseme(pre(o_{i+1})).
* DSC (Eq. 6): both nodes time-warped to ``SHAPE_POINTS`` samples (``nodes``),
  blended linearly from o_i into pre(o_{i+1}), and the second derivative's norm
  integrated over relative time: (M − 1) Σ_m ‖Δ²g_m‖.
* PVC (Eq. 7–9) = α3·PGap + VGap: the distance between o_i's last and o_{i+1}'s
  first frame, and between their velocities (per second). The paper sums marker
  distances; our channels are scalars, so the gaps are Euclidean in the
  orthonormal motion basis, i.e. the distance of the projected channel frames.
* OC (Table II): 0 when the node's phoneme is P_i or P_i is silence; α4·α5·PNT
  when their visemes agree (0 < α4 < 1); α5·PNT otherwise. EMP (Eq. 5): 0 when
  the node's emotion is E_i, α6·PNT otherwise. B (Eq. 10): a constrained index
  admits only its node, which the search applies by removing every other
  candidate (the huge penalty made exact); contaminated nodes are removed alike.
* PNT, the unit penalty, is fixed at training: the median PVC (α3 = 1) between
  random node pairs, so the α's weigh costs of one scale.

Δ²g_m is linear in a and p, so it splits into a part of a and a part of p
(``nodes.blend_halves``, precomputed per node at load): DSC costs one sum of M − 2
norms per pair.

Bounds (``NodeBounds``): TC(a, b) is never negative, and for every a it is at
most ``into[b]``; for every c, TC(b, c) is at most ``out_of[b]``. They come from
the triangle inequality: DSC(a, p) ≤ (M − 1) Σ_m (‖L_a,m‖ + ‖R_p,m‖), and the
gaps are bounded through the centroid of all first (last) frames and their
largest distance from it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import njit

from .nodes import SILENCE_INDEX, VISEME_OF_PHONEME, NodeDatabase, NodeFeatures

ALPHA_NAMES = ("alpha1", "alpha2", "alpha3", "alpha4", "alpha5", "alpha6")
PNT_SAMPLES = 2000


@dataclass(frozen=True)
class Weights:
    """α1..α6 (``alphas``, (6,)) and the unit penalty ``pnt``."""

    alphas: np.ndarray
    pnt: float

    def packed(self) -> np.ndarray:
        """(α1·PNT, α2, α3, PNT, α4·α5·PNT, α5·PNT, α6·PNT), the kernels' view."""
        a1, a2, a3, a4, a5, a6 = (float(value) for value in self.alphas)
        p = self.pnt
        return np.array([a1 * p, a2, a3, p, a4 * a5 * p, a5 * p, a6 * p])


@njit(cache=True, fastmath=False)
def gap(x: np.ndarray, i: int, y: np.ndarray, j: int) -> float:
    """‖x[i] − y[j]‖ (rows read in place: a slice would cost a reference count per call)."""
    total = 0.0
    for k in range(x.shape[1]):
        difference = x[i, k] - y[j, k]
        total += difference * difference
    return math.sqrt(total)


@njit(cache=True, fastmath=False)
def direct_smoothing(leaving: np.ndarray, a: int, arriving: np.ndarray, p: int) -> float:
    """Eq. 6 from the halves of Δ²g (``nodes.blend_halves``): (M − 1) Σ_m ‖L_a,m + R_p,m‖."""
    _, interior, dims = leaving.shape
    total = 0.0
    for m in range(interior):
        squares = 0.0
        for k in range(dims):
            value = leaving[a, m, k] + arriving[p, m, k]
            squares += value * value
        total += math.sqrt(squares)
    return float(total * (interior + 1))


class TableOne(NamedTuple):
    """What Table I's TC reads, over the N nodes: ``pre`` (N,), ``viseme`` (N,), first and
    last positions and velocities (N, K), the blend's halves ``leaving`` and ``arriving``
    (N, SHAPE_POINTS − 2, K) (``nodes.NodeFeatures``) and ``packed`` (``Weights.packed``).
    Built once per search space (``search.SearchSpace.table_one``)."""

    pre: np.ndarray
    viseme: np.ndarray
    first_position: np.ndarray
    last_position: np.ndarray
    first_velocity: np.ndarray
    last_velocity: np.ndarray
    leaving: np.ndarray
    arriving: np.ndarray
    packed: np.ndarray


@njit(cache=True, fastmath=False)
def transition_cost(a: int, b: int, table: TableOne) -> float:
    """TC(a, b) by Table I."""
    p = table.pre[b]
    if p == a:
        return 0.0
    packed = table.packed
    if p < 0:
        return float(packed[0])
    cost = packed[2] * gap(table.first_position, b, table.last_position, a)
    cost += gap(table.first_velocity, b, table.last_velocity, a)
    if table.viseme[a] != table.viseme[p]:
        cost += packed[3]
    return float(cost + packed[1] * direct_smoothing(table.leaving, a, table.arriving, p))


def unary_costs(
    nodes: NodeDatabase, viseme: np.ndarray, phoneme: int, emotion: int, packed: np.ndarray
) -> np.ndarray:
    """OC(P, o) + EMP(E, o) for every node o, (N,)."""
    if phoneme == SILENCE_INDEX:
        observation = np.zeros(nodes.size)
    else:
        observation = np.where(
            nodes.phoneme == phoneme,
            0.0,
            np.where(viseme == VISEME_OF_PHONEME[phoneme], packed[4], packed[5]),
        )
    return np.asarray(observation + np.where(nodes.emotion == emotion, 0.0, packed[6]))


@dataclass(frozen=True)
class NodeBounds:
    """``into[b]`` ≥ TC(a, b) for every a; ``out_of[a]`` ≥ TC(a, c) for every c."""

    into: np.ndarray
    out_of: np.ndarray

    @classmethod
    def of(cls, nodes: NodeDatabase, features: NodeFeatures, packed: np.ndarray) -> NodeBounds:
        points = features.leaving.shape[1] + 1
        leaving = points * np.linalg.norm(features.leaving, axis=2).sum(axis=1)
        arriving = points * np.linalg.norm(features.arriving, axis=2).sum(axis=1)

        def reach(points_: np.ndarray) -> tuple[np.ndarray, float]:
            centre = points_.mean(axis=0)
            return centre, float(np.linalg.norm(points_ - centre, axis=1).max())

        last_c, last_r = reach(features.last_position)
        lastv_c, lastv_r = reach(features.last_velocity)
        first_c, first_r = reach(features.first_position)
        firstv_c, firstv_r = reach(features.first_velocity)
        a1pnt, a2, a3, pnt = packed[0], packed[1], packed[2], packed[3]
        has_pre = nodes.pre >= 0
        arriving_pre = np.where(has_pre, arriving[np.maximum(nodes.pre, 0)], 0.0)
        priced_in = (
            a2 * (leaving.max() + arriving_pre)
            + a3 * (np.linalg.norm(features.first_position - last_c, axis=1) + last_r)
            + np.linalg.norm(features.first_velocity - lastv_c, axis=1)
            + lastv_r
            + pnt
        )
        into = np.where(has_pre, priced_in, a1pnt)
        priced_out = (
            a2 * (leaving + (arriving[nodes.pre[has_pre]].max() if has_pre.any() else 0.0))
            + a3 * (np.linalg.norm(features.last_position - first_c, axis=1) + first_r)
            + np.linalg.norm(features.last_velocity - firstv_c, axis=1)
            + firstv_r
            + pnt
        )
        out_of = np.maximum(priced_out, a1pnt) if (~has_pre).any() else priced_out
        margin = 1.0 + 1e-9  # rounding of the bounds never prunes a node that could be best
        return cls(np.asarray(into * margin + 1e-12), np.asarray(out_of * margin + 1e-12))


def unit_penalty(features: NodeFeatures, seed: int = 0) -> float:
    """PNT: the median of PGap + VGap over random node pairs (the scale of a join)."""
    n = len(features.viseme)
    rng = np.random.default_rng(seed)
    a = rng.integers(0, n, PNT_SAMPLES)
    b = rng.integers(0, n, PNT_SAMPLES)
    gaps = np.linalg.norm(features.first_position[b] - features.last_position[a], axis=1)
    gaps += np.linalg.norm(features.first_velocity[b] - features.last_velocity[a], axis=1)
    value = float(np.median(gaps))
    return value if value > 0 else 1.0
