"""The causal rungs' raw curve r(τ) and its damped filter, compiled: one call per emitted run.

Method. The spans are rows (start, end, ω) with the committed node of each (``NO_NODE``
at a silence), kept as they arrive. For a frame at t the raw curve is read at τ = t + shift:
the latest span begun by τ (the last with start < τ − 10⁻⁹, else the first) is found by
bisection; a node span gives its node's frames time-warped over the span (``nodes.warp_node``
written per row: the same products and sums), a silence the last frame of the node before
it, or the rest pose when there is none. The filter then steps to t toward that row at the
span's ω (``damped.pull_toward``, as ``damped.filter_raw`` steps it), the first frame of a
request resting on its raw row. The work is that of the frames emitted, whatever the
request's length.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from ...numerics.resample import blend_into, bracket
from ..damped import pull_toward

_STARTED = 1e-9
START, END, OMEGA = 0, 1, 2
"""Columns of a span row."""


class NodeCurves(NamedTuple):
    """What the raw curve reads of a model: the nodes' ``frames`` (F, K) and ``offsets``
    (N + 1,) (``nodes.NodeDatabase``) and the ``rest`` pose (K,). Built once per model."""

    frames: np.ndarray
    offsets: np.ndarray
    rest: np.ndarray


@njit(cache=True)
def _begun(rows: np.ndarray, count: int, at: float) -> int:
    """The last of the first ``count`` spans with start < at − 10⁻⁹, else 0."""
    low, high = 0, count
    limit = at - _STARTED
    while low < high:
        middle = (low + high) // 2
        if rows[middle, START] < limit:
            low = middle + 1
        else:
            high = middle
    return max(low - 1, 0)


@njit(cache=True)
def _raw_row(
    at: float, k: int, rows: np.ndarray, nodes: np.ndarray, curves: NodeCurves, out: np.ndarray
) -> None:
    """r(at) into ``out``, span k being the latest begun by ``at``."""
    frames, offsets = curves.frames, curves.offsets
    node = nodes[k]
    if node < 0:
        held = nodes[k - 1] if k > 0 else -1
        if held >= 0:
            out[:] = frames[offsets[held + 1] - 1]
        else:
            out[:] = curves.rest
        return
    first = offsets[node]
    last = offsets[node + 1] - 1
    relative = (at - rows[k, START]) / (rows[k, END] - rows[k, START])
    position = min(max(relative, 0.0), 1.0) * (last - first)
    low, high, fraction = bracket(position, last - first)
    blend_into(out, frames, first + low, first + high, fraction)


@njit(cache=True)
def raw_rows(
    at: np.ndarray,
    rows: np.ndarray,
    nodes: np.ndarray,
    curves: NodeCurves,
    raw: np.ndarray,
    begun: np.ndarray,
) -> None:
    """r at each of ``at`` into ``raw``, and the latest span begun at each into ``begun``."""
    for index in range(len(at)):
        k = _begun(rows, len(nodes), at[index])
        begun[index] = k
        _raw_row(at[index], k, rows, nodes, curves, raw[index])


@njit(cache=True)
def follow_raw(
    first: int,
    stop: int,
    fps: float,
    shift: float,
    rows: np.ndarray,
    nodes: np.ndarray,
    curves: NodeCurves,
    x: np.ndarray,
    v: np.ndarray,
    t: float,
    at_rest: bool,
    out: np.ndarray,
) -> None:
    """The filter's values at frames ``first`` .. ``stop`` − 1 (time i / fps) into ``out``,
    following r(t + ``shift``) from its value ``x`` and velocity ``v`` at time ``t`` (both
    updated); ``at_rest``: frame ``first`` starts the request, resting on its raw row."""
    raw = np.empty(curves.frames.shape[1])
    previous = t
    for row in range(stop - first):
        time = (first + row) / fps
        at = time + shift
        k = _begun(rows, len(nodes), at)
        _raw_row(at, k, rows, nodes, curves, raw)
        if row == 0 and at_rest:
            x[:] = raw
            v[:] = 0.0
        else:
            dt = time - previous
            w = rows[k, OMEGA]
            for column in range(len(x)):
                x[column], v[column] = pull_toward(x[column], v[column], raw[column], w, dt)
        out[row] = x
        previous = time
