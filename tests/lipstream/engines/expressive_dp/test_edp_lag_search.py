"""The fixed-lag search that reuses the last window's steps (``lag_search``) against the old
way, the whole window searched again every call (``search.search``), as the expectation: the
same committed nodes, windows, costs and frames, on random small databases (ties made
common by integer, clustered or copied frames) and on the trained demo model, in several chunkings,
with emotions, constraints and contamination."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lipstream.engines.base import Model
from lipstream.engines.expressive_dp import ExpressiveDpModel
from lipstream.engines.expressive_dp.contamination import Contamination
from lipstream.engines.expressive_dp.fast_step import (
    PRICED,
    SURE,
    Layer,
    Ranked,
    fast_step,
    lag_step,
)
from lipstream.engines.expressive_dp.lag_search import LagMemory
from lipstream.engines.expressive_dp.search import LayerSpec, SearchSpace, search
from lipstream.engines.expressive_dp.synthesizer import PathSynthesizer, extend_path
from lipstream.phonemes import PHONEME_INDEX
from lipstream.timeline import EMOTIONS

from .edp_synthetic import PHONEMES, random_space

SILENCE = PHONEME_INDEX["sil"]


def _layers(
    rng: np.random.Generator, count: int, excluded: np.ndarray, constrain: bool, silences: bool
) -> list[LayerSpec]:
    free = np.flatnonzero(~excluded)
    layers = []
    for _ in range(count):
        if silences and rng.random() < 0.12:
            layers.append(LayerSpec(SILENCE, 0))
            continue
        pinned = int(rng.choice(free)) if constrain and rng.random() < 0.15 else -1
        layers.append(LayerSpec(int(rng.choice(PHONEMES[:4])), int(rng.integers(0, 2)), pinned))
    return layers


def _space(rng: np.random.Generator, n: int, dims: int, frames: str) -> SearchSpace:
    kinds = {"coarse": frames == "coarse", "tight": frames == "tight", "copies": frames == "copies"}
    return random_space(rng, n, dims, **kinds)


def _chunks(rng: np.random.Generator, count: int, chunking: str) -> Iterator[int]:
    """The number of layers known after each call: one more, up to three more, or all."""
    known = 0
    while known < count:
        step = {"one": 1, "few": int(rng.integers(1, 4)), "all": count}[chunking]
        known = min(count, known + step)
        yield known


def _stream(
    space: SearchSpace,
    layers: list[LayerSpec],
    excluded: np.ndarray,
    lag: int | None,
    chunking: str,
    memory: LagMemory | None,
    seed: int,
) -> list[int]:
    path: list[int] = []
    rng = np.random.default_rng(seed)
    for known in _chunks(rng, len(layers), chunking):
        extend_path(space, layers[len(path) : known], excluded, lag, path, False, None, memory)
    extend_path(space, layers[len(path) :], excluded, lag, path, True, None, memory)
    return path


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    lag=st.sampled_from([1, 2, 3, 4, 6]),
    dims=st.sampled_from([2, 3, 14]),
    frames=st.sampled_from(["normal", "coarse", "tight", "copies"]),
    constrain=st.booleans(),
    contaminate=st.booleans(),
    chunking=st.sampled_from(["one", "few", "all"]),
)
def test_the_reusing_search_commits_the_nodes_of_the_full_re_search(
    seed: int,
    lag: int,
    dims: int,
    frames: str,
    constrain: bool,
    contaminate: bool,
    chunking: str,
) -> None:
    rng = np.random.default_rng(seed)
    n = 60
    space = _space(rng, n, dims, frames)
    excluded = np.zeros(n, dtype=bool)
    if contaminate:
        excluded[rng.choice(n, size=n // 5, replace=False)] = True
    layers = _layers(rng, 30, excluded, constrain, silences=True)
    expected = _stream(space, layers, excluded, lag, chunking, None, seed)
    assert _stream(space, layers, excluded, lag, chunking, LagMemory(n), seed) == expected


@pytest.mark.parametrize("frames", ["normal", "coarse", "tight", "copies"])
def test_every_window_is_the_full_searchs_window(frames: str) -> None:
    """Window after window (one layer further each, from the node the last committed), the
    path and its cost are those of ``search`` to the last bit, and later windows reuse most
    steps (fewer nodes priced than the full search prices)."""
    reused = 0
    for seed in range(6):
        rng = np.random.default_rng(seed)
        n = 80
        space = _space(rng, n, 3, frames)
        excluded = np.zeros(n, dtype=bool)
        layers = _layers(rng, 40, excluded, False, silences=False)
        memory = LagMemory(n)
        before = -1
        for start in range(len(layers) - 4):
            window = layers[start : start + 5]
            full = search(space, window, excluded, before=before)
            found = memory.search(space, window, excluded, start, before)
            assert found.path.tolist() == full.path.tolist()
            assert found.cost == full.cost
            reused += found.candidates < full.candidates
            before = int(found.path[0])
    assert reused > 100


@pytest.mark.parametrize("frames", ["normal", "coarse", "copies"])
def test_windows_of_other_lengths_skips_and_restarts_are_the_full_searchs(frames: str) -> None:
    """A stream's windows (its layers fixed, with constraints and contamination) of three to
    six layers, so that a layer that was last is a middle one next time and back, that skip a
    layer or restart without a node before, each against ``search`` of the same window: the
    same path and cost to the last bit, never more nodes priced than the full search."""
    for seed in range(8):
        rng = np.random.default_rng(100 + seed)
        n = 70
        space = _space(rng, n, 3, frames)
        excluded = np.zeros(n, dtype=bool)
        if seed % 2:
            excluded[rng.choice(n, size=n // 6, replace=False)] = True
        layers = _layers(rng, 40, excluded, seed % 4 > 1, silences=False)
        memory = LagMemory(n)
        before, start = -1, 0
        while start + 3 <= len(layers):
            window = layers[start : start + int(rng.integers(3, 7))]
            full = search(space, window, excluded, before=before)
            found = memory.search(space, window, excluded, start, before)
            assert found.path.tolist() == full.path.tolist(), (seed, start)
            assert found.cost == full.cost, (seed, start)
            assert found.candidates <= full.candidates
            jump = int(rng.choice([1, 1, 1, 2, 0]))
            before = int(found.path[0]) if jump == 1 else -1
            start += max(jump, 1)


@pytest.fixture(scope="module")
def model(trained_models: dict[str, Model]) -> ExpressiveDpModel:
    found = trained_models["expressive-dp"]
    assert isinstance(found, ExpressiveDpModel)
    return found


def _spans(seed: int, count: int) -> list[tuple[Any, ...]]:
    """Client spans with gaps, silences and per-span emotions."""
    rng = np.random.default_rng(seed)
    labels = "HH AH0 L OW1 W ER1 D M AA1 P B IY1 S T F V K EH1 N Z SH AY1 UW1".split()
    spans: list[tuple[Any, ...]] = []
    t = 0.0
    for _ in range(count):
        label = "sil" if rng.random() < 0.08 else labels[int(rng.integers(len(labels)))]
        t += 0.05 if rng.random() < 0.05 else 0.0
        length = float(rng.uniform(0.04, 0.18))
        emotion = EMOTIONS[int(rng.integers(len(EMOTIONS)))] if rng.random() < 0.5 else None
        spans.append((label, t, t + length, emotion))
        t += length
    return spans


def _synthesize(
    model: ExpressiveDpModel,
    spans: list[tuple[Any, ...]],
    chunk: int,
    reuse: bool,
    **options: Any,
) -> tuple[str, float, np.ndarray]:
    synthesizer = model.start(fps=60, emotion="happy", **options)
    assert isinstance(synthesizer, PathSynthesizer)
    if not reuse:
        synthesizer.memory = None
    out = []
    for start in range(0, len(spans), chunk):
        synthesizer.feed(spans[start : start + chunk])
        out.append(synthesizer.frames())
    out.append(synthesizer.finish())
    stats = synthesizer.stats
    return str(stats["nodes"]), float(stats["path_cost"]), np.concatenate(out)


@pytest.mark.parametrize("contaminated", [False, True])
def test_the_demo_models_streams_are_those_of_the_full_re_search(
    model: ExpressiveDpModel, contaminated: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Nodes, path cost and frames (bit for bit) on every fixed-lag rung and the full search,
    one span per message, three, and all at once, with constraints."""
    if contaminated:
        contamination = Contamination(model.nodes.size, None)
        rng = np.random.default_rng(3)
        contamination.change(rng.choice(model.nodes.size, 60, replace=False).tolist(), [])
        monkeypatch.setattr(model, "contamination", contamination)
    spans = _spans(11, 45)
    free = np.flatnonzero(~model.contamination.mask())
    constraints = {"4": int(free[3]), "20": int(free[-5])}
    for lag in [1, 2, 4, 6, "full"]:
        for chunk in [1, 3, len(spans)]:
            for extra in [{}, {"constraints": constraints}]:
                options = {"lag": lag, **extra}
                new = _synthesize(model, spans, chunk, True, **options)
                old = _synthesize(model, spans, chunk, False, **options)
                assert new[:2] == old[:2], (lag, chunk, extra)
                assert new[2].tobytes() == old[2].tobytes(), (lag, chunk, extra)


@pytest.mark.parametrize("gap", [0.0, 1e-12, 1e-6])
def test_a_best_predecessor_is_sure_only_when_it_wins_by_the_margin(gap: float) -> None:
    """Two predecessors whose costs into b differ by ``gap`` (relative): the step takes the
    cheaper (the earlier on a tie) and calls it sure only past ``SURE``; the next window's
    step scans an unsure node again and takes a sure one as given, with the scan's φ."""
    rng = np.random.default_rng(5)
    n = 30
    space = random_space(rng, n, 3)
    pre = space.nodes.pre
    b = int(np.flatnonzero(pre >= 0)[0])
    a1, a2 = (int(a) for a in np.flatnonzero((np.arange(n) != pre[b]) & (np.arange(n) != b))[:2])
    c1, c2 = space.tc(a1, b), space.tc(a2, b)
    base = max(c1, c2) + 1.0
    prev_f = np.array([base - c1, base - c2 + gap * base])
    order = np.argsort(prev_f, kind="stable")
    prev_nodes, prev_f = np.array([a1, a2])[order], prev_f[order]
    roots = np.full(2, 7)
    scratch = (np.full(n, -1, dtype=np.int64), np.full(n, -1, dtype=np.int64))
    none = np.zeros(0, dtype=np.int64)
    empty = Ranked(
        none,
        np.zeros(0),
        none,
        np.zeros(0, dtype=bool),
        np.zeros(0, dtype=np.int8),
        np.zeros((0, 4)),
        none,
    )
    previous = Ranked(prev_nodes, prev_f, none, empty.sure, empty.kind, empty.terms, roots)
    candidates = Layer(np.array([b]), np.zeros(1))

    def step(known: Ranked, then: Ranked) -> tuple[Ranked, int]:
        return lag_step(previous, candidates, space.joins, known, then, 7, *scratch)

    made, scanned = step(empty, empty)
    nodes, f, back, sure, kind, terms, root = made
    assert scanned == 1 and root[0] == 7
    assert prev_nodes[back[0]] == (a1 if gap > 0 or order[0] == 0 else a2)
    assert bool(sure[0]) == (gap > SURE)
    again, rescanned = step(made, previous)
    assert rescanned == (0 if gap > SURE else 1)
    assert again.costs.tobytes() == f.tobytes()
    assert again.back.tolist() == back.tolist()


def test_a_node_scanned_again_on_a_tie_takes_the_scans_first_pair_not_its_last_best() -> None:
    """Two predecessors of one pattern and one phoneme (copies: the same join into b to the
    bit) with the same φ tie exactly; ``fast_step`` keeps the first in its order. The last
    window's best pair into b was the second, by another root than the one committed, so b
    is scanned again: the step takes the first, as ``fast_step`` does, with its φ, and does
    not call it sure (a scan seeded with the last window's pair would keep the second)."""
    rng = np.random.default_rng(3)
    n = 60
    space = random_space(rng, n, 3, copies=True)
    leaving, viseme, pre = space.records.leaving, space.features.viseme, space.nodes.pre
    pairs = [
        (b, a1, a2)
        for b in np.flatnonzero(pre >= 0).tolist()
        for a1 in range(n)
        for a2 in range(a1 + 1, n)
        if pre[b] not in (a1, a2)
        and viseme[a1] == viseme[a2]
        and np.array_equal(leaving[a1], leaving[a2])
    ]
    assert pairs, "the copies database has interchangeable nodes"
    b, a1, a2 = pairs[0]
    prev_nodes = np.array([a1, a2])
    prev_f = np.array([1.0, 1.0])
    candidates = Layer(np.array([b]), np.zeros(1))
    plain_nodes, plain_f, plain_back = fast_step(
        Layer(prev_nodes, prev_f), candidates, space.joins, np.full(n, -1, dtype=np.int64)
    )
    assert plain_back.tolist() == [0]

    none = np.zeros(0, dtype=np.int64)
    no_sure, no_kind, no_terms = (
        np.zeros(0, dtype=bool),
        np.zeros(0, dtype=np.int8),
        np.zeros((0, 4)),
    )
    empty = Ranked(none, np.zeros(0), none, no_sure, no_kind, no_terms, none)
    previous = Ranked(prev_nodes, prev_f, none, no_sure, no_kind, no_terms, np.full(2, 7))
    scratch = (np.full(n, -1, dtype=np.int64), np.full(n, -1, dtype=np.int64))
    cold, _ = lag_step(previous, candidates, space.joins, empty, empty, 7, *scratch)
    then = previous._replace(root=np.full(2, 8))
    known = Ranked(
        np.array([b]),
        cold.costs,
        np.array([1]),
        np.ones(1, dtype=bool),
        np.full(1, PRICED, dtype=np.int8),
        cold.terms,
        np.full(1, 8),
    )
    made, scanned = lag_step(previous, candidates, space.joins, known, then, 7, *scratch)
    assert scanned == 1
    assert made.back.tolist() == [0]
    assert made.costs.tobytes() == plain_f.tobytes()
    assert made.nodes.tolist() == plain_nodes.tolist()
    assert not made.sure[0]
