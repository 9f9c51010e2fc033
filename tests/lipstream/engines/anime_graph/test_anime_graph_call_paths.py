"""anime-graph's fast streamed calls against its general path, call by call.

The causal call (``causal_call.causal_step``: pick, place, emit in one compiled call) and the
greedy call without audio (``_suffix_tiles``: kept kernel arguments, linear placements) must
give exactly what the general path gives: ``_decide`` with ``SuffixMatcher.tiles`` built from
a fresh ``Ranking``, ``plan_join`` and ``MotionTrack.append`` of a built linear warp.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from lipstream.corpus import Corpus
from lipstream.engines.anime_graph import AnimeGraphEngine, AnimeGraphModel
from lipstream.engines.anime_graph.search import SuffixMatcher
from lipstream.engines.anime_graph.synthesizer import AnimeGraphSynthesizer, _Searcher
from lipstream.engines.anime_graph.track import Placement
from lipstream.engines.anime_graph.warp import linear_warp
from lipstream.timeline import PhonemeSpan
from tests.lipstream.engines.anime_graph.anime_synthetic import make_corpus, make_spans

RECORDED = ("neutral", "happy")
FPS = 60.0
OPTION_SETS: list[dict[str, Any]] = [
    {"causal": True},
    {"causal": True, "lead_ms": 40.0},
    {"causal": True, "blend": False},
    {"max_tile": 10},
    {"max_tile": 2},
    {"max_tile": 1, "smooth": False},
    {"max_tile": 3, "blend": False},
]


@pytest.fixture(scope="module")
def corpus() -> Corpus:
    return make_corpus(seed=5, n_utterances=24, emotions=RECORDED)


@pytest.fixture(scope="module")
def model(corpus: Corpus) -> AnimeGraphModel:
    return AnimeGraphEngine(clusters=30, max_tile=6).fit(corpus)


def general(synthesizer: AnimeGraphSynthesizer) -> AnimeGraphSynthesizer:
    """``synthesizer`` with its fast paths replaced by the general ones."""

    def causal_step(
        searcher: _Searcher, matcher: SuffixMatcher, placed: int, total: int
    ) -> np.ndarray:
        synthesizer._decide()
        return synthesizer._emit_causal()

    def suffix_tiles(
        searcher: _Searcher,
        matcher: SuffixMatcher,
        start: int,
        stop: int,
        closed: bool,
        continuing: int | None,
        ranked: int | None,
    ) -> list[list[int]] | None:
        ranking = synthesizer.ranking(searcher.graph, start, stop)
        tiles = matcher.tiles(
            synthesizer.query,
            start,
            stop,
            synthesizer.options.max_tile,
            continuing,
            ranking,
            ranked,
            final_only=not closed,
        )
        return [tile.tolist() for tile in tiles] or None

    def place(position: int, anime: int, warp: Any) -> None:
        span = synthesizer.spans[position]
        animes = synthesizer.model.animes
        built = linear_warp(
            span.start, span.end, float(animes.start[anime]), float(animes.end[anime])
        )
        placed = len(synthesizer.track)
        AnimeGraphSynthesizer._place(synthesizer, position, anime, built)
        assert len(synthesizer.track) == placed + 1

    synthesizer._causal_step = causal_step  # type: ignore[method-assign]  # spies on the steps
    synthesizer._suffix_tiles = suffix_tiles  # type: ignore[method-assign]  # spies on the steps
    synthesizer._place = place  # type: ignore[method-assign]  # spies on the steps
    return synthesizer


def chunkings(count: int, rng: np.random.Generator) -> Iterator[list[int]]:
    """Chunk sizes: one span per message, up to four (some empty), the whole request."""
    yield [1] * count
    sizes: list[int] = []
    while sum(sizes) < count:
        sizes.append(int(rng.integers(0, 5)))
    yield sizes
    yield [count]


def streams(seed: int) -> Iterator[list[PhonemeSpan]]:
    """Random phonemes, some with a pause before them, a few runs of another emotion."""
    rng = np.random.default_rng(seed)
    for _ in range(3):
        spans = make_spans(rng, int(rng.integers(4, 30)))
        shifted, gap = [], 0.0
        for index, span in enumerate(spans):
            if index and rng.random() < 0.1:
                gap += float(np.round(rng.uniform(0.02, 0.2), 3))
            emotion = "happy" if 5 <= index < 9 and seed % 2 else None
            shifted.append(PhonemeSpan(span.phoneme, span.start + gap, span.end + gap, emotion))
        yield shifted


def run(synthesizer: AnimeGraphSynthesizer, spans: list[PhonemeSpan], sizes: list[int]) -> Any:
    calls, start = [], 0
    for size in sizes:
        synthesizer.feed(spans[start : start + size])
        start += size
        calls.append(synthesizer.frames())
    calls.append(synthesizer.finish())
    stats = {key: value for key, value in synthesizer.stats.items() if key != "search_ms"}
    return calls, stats, synthesizer


@pytest.mark.parametrize("options", OPTION_SETS, ids=str)
@pytest.mark.parametrize("seed", [1, 2])
def test_the_fast_calls_give_the_general_paths_frames(
    model: AnimeGraphModel, options: dict[str, Any], seed: int
) -> None:
    rng = np.random.default_rng(seed)
    for spans in streams(seed):
        offline = model.synthesize(spans, fps=FPS, **options).frames
        for sizes in chunkings(len(spans), rng):
            fast, fast_stats, fast_synth = run(model.start(fps=FPS, **options), spans, sizes)
            slow, slow_stats, slow_synth = run(
                general(model.start(fps=FPS, **options)), spans, sizes
            )
            assert [call.tobytes() for call in fast] == [call.tobytes() for call in slow]
            assert fast_stats == slow_stats
            assert fast_synth.nodes == slow_synth.nodes
            assert fast_synth.track.joins == slow_synth.track.joins
            assert _placements(fast_synth.track.placements) == _placements(
                slow_synth.track.placements
            )
            assert np.concatenate(fast).tobytes() == offline.tobytes()


def _placements(placements: list[Placement]) -> list[tuple[Any, ...]]:
    return [
        (p.start, p.end, p.anime, p.warp.target.tobytes(), p.warp.source.tobytes())
        for p in placements
    ]


def test_the_general_path_is_the_one_replaced(model: AnimeGraphModel) -> None:
    """``general`` really takes the general path: its calls never reach the fast ones."""
    spans = make_spans(np.random.default_rng(4), 10)
    for options in ({"causal": True}, {"max_tile": 4}):
        synthesizer = general(model.start(fps=FPS, **options))
        for name in ("_causal_step", "_suffix_tiles"):
            assert getattr(AnimeGraphSynthesizer, name) is not getattr(synthesizer, name)
        run(synthesizer, spans, [1] * len(spans))
        assert len(synthesizer.track) == len(spans)
