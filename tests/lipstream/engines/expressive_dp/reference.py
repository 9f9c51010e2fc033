"""Eq. 4 of one motion-node path, summed term by term: the oracle the searches are tested against.

Sketch: walk the path layer by layer, adding each node's unary cost (OC + EMP, infinite when a
constraint excludes it) and the TC from the node before; a silence costs nothing and breaks the
chain, so no TC crosses it.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from lipstream.engines.expressive_dp.search import NO_NODE, LayerSpec, SearchSpace


def path_cost(
    space: SearchSpace,
    layers: Sequence[LayerSpec],
    path: Sequence[int] | np.ndarray,
    before: int = -1,
) -> float:
    """Eq. 4 of ``path`` (infinite when it breaks a constraint); silences cost nothing and
    no TC crosses them. ``before`` is a node fixed ahead of the first layer."""
    excluded = np.zeros(space.nodes.size, dtype=bool)
    total = 0.0
    previous = before
    for layer, node in zip(layers, path):
        if layer.silent:
            previous = NO_NODE
            continue
        total += float(space.unary(layer, excluded)[node])
        if previous >= 0:
            total += space.tc(int(previous), int(node))
        previous = node
    return total
