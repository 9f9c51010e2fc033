"""Random small node databases, and Table I / Eq. 6 written out by plain loops (independent of
the engine's compiled and split forms)."""

from __future__ import annotations

import itertools
import math
from dataclasses import replace

import numpy as np

from lipstream.engines.expressive_dp.costs import NodeBounds, Weights
from lipstream.engines.expressive_dp.nodes import (
    SHAPE_POINTS,
    VISEME_OF_PHONEME,
    NodeDatabase,
    NodeFeatures,
)
from lipstream.engines.expressive_dp.search import LayerSpec, SearchSpace
from lipstream.phonemes import PHONEME_INDEX

PHONEMES = [PHONEME_INDEX[p] for p in ("P", "B", "AA", "S", "sil")]
SPEECH = PHONEMES[:4]


def random_database(rng: np.random.Generator, n: int, dims: int = 3) -> NodeDatabase:
    """``n`` nodes of 2..5 frames, phonemes among P B AA S, random emotions, and captured
    neighbour chains of random lengths."""
    counts = rng.integers(2, 6, n)
    offsets = np.concatenate([[0], np.cumsum(counts)])
    pre = np.full(n, -1)
    for node in range(1, n):
        if rng.random() < 0.5:
            pre[node] = node - 1
    suc = np.full(n, -1)
    suc[pre[pre >= 0]] = np.flatnonzero(pre >= 0)
    return NodeDatabase(
        phoneme=rng.choice(SPEECH, n),
        emotion=rng.integers(0, 4, n),
        previous=rng.choice(PHONEMES, n),
        next=rng.choice(PHONEMES, n),
        pre=pre,
        suc=suc,
        offsets=offsets,
        frames=rng.normal(size=(int(offsets[-1]), dims)),
        fps=100.0,
    )


def random_space(
    rng: np.random.Generator,
    n: int,
    dims: int = 3,
    coarse: bool = False,
    tight: bool = False,
    copies: bool = False,
) -> SearchSpace:
    """A random database and weights; ``coarse`` rounds the frames to integers, so that many
    gaps, and so many path costs, tie exactly; ``tight`` draws every frame near one of three
    poses, so that many joins cost nearly the same and every coordinate counts; ``copies``
    gives every node three frames, one of four patterns, so that nodes of one pattern,
    phoneme and emotion are interchangeable and whole paths tie exactly."""
    nodes = random_database(rng, n, dims)
    if copies:
        patterns = np.round(rng.normal(size=(4, 3, dims)))
        nodes = replace(
            nodes,
            offsets=np.arange(n + 1) * 3,
            frames=patterns[rng.integers(0, 4, n)].reshape(-1, dims),
            phoneme=rng.choice(SPEECH[:2], n),
            emotion=rng.integers(0, 2, n),
        )
    if coarse:
        nodes.frames[:] = np.round(nodes.frames)
    if tight:
        poses = rng.normal(size=(3, dims))
        picked = poses[rng.integers(0, 3, len(nodes.frames))]
        nodes.frames[:] = picked + 0.002 * rng.normal(size=nodes.frames.shape)
    features = NodeFeatures.of(nodes)
    alphas = np.exp(rng.uniform(np.log(0.05), np.log(5.0), 6))
    alphas[3] = rng.uniform(0.05, 0.95)
    packed = Weights(alphas, float(rng.uniform(0.5, 3.0))).packed()
    return SearchSpace(nodes, features, NodeBounds.of(nodes, features, packed), packed)


def shape(nodes: NodeDatabase, node: int) -> np.ndarray:
    frames = nodes.node_frames(node)
    source = np.linspace(0.0, 1.0, len(frames))
    target = np.linspace(0.0, 1.0, SHAPE_POINTS)
    return np.stack([np.interp(target, source, frames[:, k]) for k in range(frames.shape[1])], 1)


def loop_tc(space: SearchSpace, a: int, b: int) -> float:
    """Table I by hand; DSC blends the resampled nodes and sums |Δ²| over relative time."""
    nodes, packed = space.nodes, space.packed
    a1pnt, a2, a3, pnt = packed[0], packed[1], packed[2], packed[3]
    p = int(nodes.pre[b])
    if p == a:
        return 0.0
    if p < 0:
        return float(a1pnt)
    fa, fb = nodes.node_frames(a), nodes.node_frames(b)
    pgap = float(np.linalg.norm(fb[0] - fa[-1]))
    vgap = float(np.linalg.norm((fb[1] - fb[0]) * nodes.fps - (fa[-1] - fa[-2]) * nodes.fps))
    sa, sp = shape(nodes, a), shape(nodes, p)
    dims = sa.shape[1]
    m = SHAPE_POINTS
    blend = [(1 - i / (m - 1)) * sa[i] + i / (m - 1) * sp[i] for i in range(m)]
    dsc = sum(
        math.sqrt(
            sum((blend[i - 1][k] - 2 * blend[i][k] + blend[i + 1][k]) ** 2 for k in range(dims))
        )
        for i in range(1, m - 1)
    ) * (m - 1)
    same = VISEME_OF_PHONEME[nodes.phoneme[a]] == VISEME_OF_PHONEME[nodes.phoneme[p]]
    return float(a2 * dsc + a3 * pgap + vgap + (0.0 if same else pnt))


def loop_unary(space: SearchSpace, layer: LayerSpec, node: int) -> float:
    """Table II and Eq. 5 by hand (infinite off a constraint)."""
    nodes, packed = space.nodes, space.packed
    if layer.constrained >= 0 and node != layer.constrained:
        return math.inf
    if layer.phoneme == PHONEME_INDEX["sil"] or nodes.phoneme[node] == layer.phoneme:
        observation = 0.0
    elif VISEME_OF_PHONEME[nodes.phoneme[node]] == VISEME_OF_PHONEME[layer.phoneme]:
        observation = packed[4]
    else:
        observation = packed[5]
    return float(observation + (0.0 if nodes.emotion[node] == layer.emotion else packed[6]))


def brute_force(
    space: SearchSpace, layers: list[LayerSpec], excluded: np.ndarray
) -> tuple[float, tuple[int, ...]]:
    """The cheapest path by enumerating every path (tiny problems only); a silence layer has
    no node (-1) and cuts the chain of TCs."""
    silent = PHONEME_INDEX["sil"]
    allowed = [n for n in range(space.nodes.size) if not excluded[n]]
    choices = [[-1] if layer.phoneme == silent else range(space.nodes.size) for layer in layers]
    best: tuple[float, tuple[int, ...]] = (math.inf, ())
    for path in itertools.product(*choices):
        if any(
            layer.constrained < 0 and node >= 0 and node not in allowed
            for layer, node in zip(layers, path)
        ):
            continue
        cost = sum(loop_unary(space, layer, node) for layer, node in zip(layers, path) if node >= 0)
        cost += sum(loop_tc(space, a, b) for a, b in itertools.pairwise(path) if a >= 0 and b >= 0)
        if cost < best[0]:
            best = (cost, path)
    return best
