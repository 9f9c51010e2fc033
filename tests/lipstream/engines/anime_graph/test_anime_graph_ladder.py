"""anime-graph's fidelity ladder: each rung's declared lookahead is what its options need."""

from __future__ import annotations

import math
from itertools import pairwise

import numpy as np
import pytest

from lipstream.audio import Audio
from lipstream.engines.anime_graph import AnimeGraphEngine, AnimeGraphModel
from lipstream.engines.base import Lookahead, Rung, SynthesisRequest, final_until, frames_before
from lipstream.errors import InvalidRequestError
from lipstream.server.budget import lookahead_ms
from lipstream.timeline import PhonemeSpan
from tests.lipstream.engines.anime_graph.anime_synthetic import (
    make_corpus,
    make_spans,
    render_audio,
)

FPS = 120.0  # the corpus's rate, so output frames sit on the model grid
OFF_GRID_FPS = 97.0  # frames between model samples, which interpolation waits one more for
H = 12  # smoothing half-width in model frames: round(0.1 s * 120 fps)
CAUSAL_OPTIONS = {"search": "greedy", "max_tile": 1, "causal": True}
CAUSAL_NAMES = ["causal_lead", "causal"]


def causal_rungs(model: AnimeGraphModel) -> list[Rung]:
    """The causal rungs, their lead worked out by hand: the damped filter's lag 2 / omega
    for the first PCA component, omega = 2 pi f / sqrt(sqrt(2) - 1) with f twice its
    learned cutoff (at least 2 Hz), at most 120 ms."""
    cutoff = 2.0 * max(float(model.cutoffs[0]), 2.0)
    omega = 2 * math.pi * cutoff / math.sqrt(math.sqrt(2) - 1)
    return [
        Rung("causal_lead", Lookahead(min(0.12, 2 / omega)), {**CAUSAL_OPTIONS, "lead_ms": 120.0}),
        Rung("causal", Lookahead(0.0), {**CAUSAL_OPTIONS, "lead_ms": 0.0}),
    ]


@pytest.fixture(scope="module")
def corpus_and_model() -> tuple[list[list[PhonemeSpan]], AnimeGraphModel]:
    corpus = make_corpus(seed=3, n_utterances=16, length=(10, 14), with_audio=False)
    model = AnimeGraphEngine(clusters=20).fit(corpus)
    return [utterance.phones for utterance in corpus.utterances], model


@pytest.fixture(scope="module")
def model(corpus_and_model: tuple[list[list[PhonemeSpan]], AnimeGraphModel]) -> AnimeGraphModel:
    return corpus_and_model[1]


def test_the_ladder_shortens_tiles_then_drops_smoothing(model: AnimeGraphModel) -> None:
    smoothed, raw = (H + 1) / FPS, 1 / FPS
    assert model.half_width == H
    assert model.fidelity_ladder() == (
        Rung("greedy_tile10", Lookahead(smoothed, 10), {"search": "greedy", "max_tile": 10}),
        Rung("greedy_tile4", Lookahead(smoothed, 4), {"search": "greedy", "max_tile": 4}),
        Rung("greedy_tile2", Lookahead(smoothed, 2), {"search": "greedy", "max_tile": 2}),
        Rung("greedy_tile1", Lookahead(smoothed, 1), {"search": "greedy", "max_tile": 1}),
        Rung(
            "greedy_tile1_unsmoothed",
            Lookahead(raw, 1),
            {"search": "greedy", "max_tile": 1, "smooth": False},
        ),
        *causal_rungs(model),
    )


def test_each_rung_waits_less_than_the_one_above(model: AnimeGraphModel) -> None:
    ladder = model.fidelity_ladder()
    greedy = [rung for rung in ladder if not rung.options.get("causal")]
    for upper, lower in pairwise(greedy):
        assert lower.lookahead.seconds <= upper.lookahead.seconds
        assert lower.lookahead.phonemes <= upper.lookahead.phonemes
        assert lower.lookahead != upper.lookahead
        for longest_phoneme_ms in (50.0, 200.0):
            assert lookahead_ms(lower, longest_phoneme_ms) < lookahead_ms(upper, longest_phoneme_ms)
    # Ordered by fidelity: below a phoneme's wait only with phonemes of a realistic length.
    for upper, lower in pairwise(ladder):
        assert lookahead_ms(lower, 200.0) < lookahead_ms(upper, 200.0)


@pytest.mark.parametrize(
    ("max_tile", "expected"),
    [
        (6, ["greedy_tile6", "greedy_tile4", "greedy_tile2", "greedy_tile1", *CAUSAL_NAMES]),
        (
            12,
            [
                "greedy_tile12",
                "greedy_tile10",
                "greedy_tile4",
                "greedy_tile2",
                "greedy_tile1",
                *CAUSAL_NAMES,
            ],
        ),
        (1, ["greedy_tile1", *CAUSAL_NAMES]),
    ],
)
def test_the_top_rung_is_the_models_own_tile_cap(max_tile: int, expected: list[str]) -> None:
    lean = AnimeGraphEngine(clusters=0, max_tile=max_tile, smoothing_window=0.0).fit(
        make_corpus(seed=2, n_utterances=4, with_audio=False)
    )
    ladder = lean.fidelity_ladder()
    assert [rung.name for rung in ladder] == expected  # no smoothing: no unsmoothed rung
    greedy = ladder[: -len(CAUSAL_NAMES)]
    assert all(rung.lookahead.seconds == 1 / lean.fps for rung in greedy)


def _stream_one_by_one(
    model: AnimeGraphModel, spans: list[PhonemeSpan], options: dict[str, object], fps: float = FPS
) -> tuple[np.ndarray, list[int]]:
    """All frames, and how many had come out after each span was fed."""
    synthesizer = model.start(SynthesisRequest(fps=fps, options=options))
    pieces, emitted = [], []
    for span in spans:
        synthesizer.feed([span])
        pieces.append(synthesizer.frames())
        emitted.append(sum(len(piece) for piece in pieces))
    pieces.append(synthesizer.finish())
    return np.concatenate(pieces), emitted


@pytest.mark.parametrize("fps", [FPS, OFF_GRID_FPS])
@pytest.mark.parametrize("graph", ["unclustered", "clustered"])
@pytest.mark.parametrize("rung_index", range(5 + len(CAUSAL_NAMES)))
def test_a_rung_emits_every_frame_its_lookahead_promises(
    model: AnimeGraphModel, graph: str, rung_index: int, fps: float
) -> None:
    rung = model.fidelity_ladder()[rung_index]
    options = {**rung.options, "graph": graph}
    for seed in (1, 2):
        spans = make_spans(np.random.default_rng(seed), 30)
        streamed, emitted = _stream_one_by_one(model, spans, options, fps)
        for index, count in enumerate(emitted):
            promised = frames_before(final_until(spans[: index + 1], rung.lookahead), fps)
            assert count >= promised, f"{rung.name}: held back after span {index}"
        offline = model.synthesize(spans, fps=fps, **options).frames
        np.testing.assert_array_equal(streamed, offline)


@pytest.mark.parametrize("rung_index", range(5))
def test_a_rung_needs_all_the_phonemes_it_declares(
    corpus_and_model: tuple[list[list[PhonemeSpan]], AnimeGraphModel], rung_index: int
) -> None:
    """A long pause, then a recorded line said again: the line is one tile, cut at the cap,
    so the frames in the pause wait for exactly ``max_tile`` phonemes of the line."""
    recordings, model = corpus_and_model
    rung = model.fidelity_ladder()[rung_index]
    line = max(recordings, key=len)
    assert len(line) > 10
    pause = 0.5
    spans = [PhonemeSpan("sil", 0.0, pause)] + [
        PhonemeSpan(span.phoneme, span.start + pause, span.end + pause) for span in line
    ]
    _, emitted = _stream_one_by_one(model, spans, dict(rung.options))
    shorter = Lookahead(rung.lookahead.seconds, rung.lookahead.phonemes - 1)
    assert any(
        count < frames_before(final_until(spans[: index + 1], shorter), FPS)
        for index, count in enumerate(emitted)
    ), rung.name


@pytest.mark.parametrize("rung_index", [3, 4])
def test_one_phoneme_tiles_need_the_whole_declared_seconds(
    model: AnimeGraphModel, rung_index: int
) -> None:
    """With one-phoneme tiles every fragment but the last is decided, so the smoothing
    half-width and the interpolation sample are the whole wait."""
    rung = model.fidelity_ladder()[rung_index]
    spans = make_spans(np.random.default_rng(5), 30)
    _, emitted = _stream_one_by_one(model, spans, dict(rung.options), OFF_GRID_FPS)
    sooner = Lookahead(rung.lookahead.seconds - 1 / FPS, rung.lookahead.phonemes)
    assert any(
        count < frames_before(final_until(spans[: index + 1], sooner), OFF_GRID_FPS)
        for index, count in enumerate(emitted)
    ), rung.name


def test_the_synthesizer_takes_max_tile_and_smoothing_from_the_request(
    model: AnimeGraphModel,
) -> None:
    spans = make_spans(np.random.default_rng(7), 20)
    for rung in model.fidelity_ladder()[: -len(CAUSAL_NAMES)]:
        synthesizer = model.start(fps=FPS, **rung.options)
        assert synthesizer.options.max_tile == rung.options["max_tile"]
        assert synthesizer.half_width == (H if rung.options.get("smooth", True) else 0)
        synthesizer.feed(spans)
        synthesizer.finish()
        tile = rung.options["max_tile"]
        assert synthesizer.stats["tiles"] >= -(-len(synthesizer.nodes) // tile)
    assert model.start(fps=FPS, causal=True, max_tile=4).options.max_tile == 1
    for rung in causal_rungs(model):
        causal = model.start(fps=FPS, **rung.options)
        assert causal.options.max_tile == 1
        causal.feed(spans)
        causal.finish()
        assert causal.stats["tiles"] == len(causal.nodes) == len(spans)
    with pytest.raises(InvalidRequestError):
        model.greedy_lookahead(0, smooth=True)


@pytest.fixture(scope="module")
def audio_model() -> AnimeGraphModel:
    return AnimeGraphEngine(clusters=0).fit(make_corpus(seed=4, n_utterances=16, length=(10, 14)))


def _stream_with_audio(
    model: AnimeGraphModel,
    spans: list[PhonemeSpan],
    audio: Audio,
    reach_s: float,
    options: dict[str, object],
) -> list[int]:
    """Frames out after each span is fed with the audio up to its end + ``reach_s``."""
    synthesizer = model.start(SynthesisRequest(fps=FPS, options=options))
    rate, sent, emitted = audio.sample_rate, 0, [0]
    for span in spans:
        until = min(len(audio.samples), round((span.end + reach_s) * rate))
        synthesizer.feed([span], Audio(audio.samples[sent:until], rate))
        sent = until
        emitted.append(emitted[-1] + len(synthesizer.frames()))
    return emitted[1:]


@pytest.mark.parametrize("rung_index", [0, 3, 4])
def test_audio_that_reaches_the_declared_wait_releases_every_promised_frame(
    audio_model: AnimeGraphModel, rung_index: int
) -> None:
    rung = audio_model.fidelity_ladder()[rung_index]
    wait = rung.lookahead.audio_seconds
    assert wait == pytest.approx(2 / 100 + 0.025 / 2)  # MFCC: two 10 ms steps, half a window
    spans = make_spans(np.random.default_rng(8), 30)
    audio = render_audio(
        spans + [PhonemeSpan("sil", spans[-1].end, spans[-1].end + 1.0)], np.random.default_rng(9)
    )
    emitted = _stream_with_audio(audio_model, spans, audio, wait, dict(rung.options))
    for index, count in enumerate(emitted):
        assert count >= frames_before(final_until(spans[: index + 1], rung.lookahead), FPS)
    if rung.name == "greedy_tile1_unsmoothed":
        # Its frames wait for the very next one-phoneme tile, which waits for its audio.
        short = _stream_with_audio(audio_model, spans, audio, wait - 0.011, dict(rung.options))
        assert any(
            count < frames_before(final_until(spans[: index + 1], rung.lookahead), FPS)
            for index, count in enumerate(short)
        ), "the declared audio wait is not needed"


@pytest.mark.parametrize(
    "options",
    [
        {"max_tile": 3},
        {"search": "pq", "pq_window": 3, "pq_advance": 1},
        {"search": "pq", "pq_window": 2, "pq_advance": 2, "smooth": False},
        {"search": "pq", "pq_window": 4, "pq_advance": 3, "graph": "clustered"},
    ],
)
def test_the_lookahead_of_any_options_is_kept(
    model: AnimeGraphModel, options: dict[str, object]
) -> None:
    lookahead = model.lookahead_for(options)
    assert lookahead is not None
    for seed in (3, 4):
        spans = make_spans(np.random.default_rng(seed), 24)
        _, emitted = _stream_one_by_one(model, spans, options, OFF_GRID_FPS)
        for index, count in enumerate(emitted):
            assert count >= frames_before(final_until(spans[: index + 1], lookahead), OFF_GRID_FPS)


def test_an_uncapped_tile_has_no_bounded_lookahead(model: AnimeGraphModel) -> None:
    assert model.lookahead_for({"max_tile": 0}) is None
    assert model.lookahead_for({}) == model.fidelity_ladder()[0].lookahead


@pytest.mark.parametrize(
    ("options", "where"),
    [
        ({"causal": True, "search": "pq"}, "options.search"),
        ({"causal": True, "lead_ms": 2000}, "options.lead_ms"),
        ({"lead_ms": 30}, "options.lead_ms"),
        ({"causal": "yes"}, "options.causal"),
    ],
)
def test_causal_options_that_would_look_ahead_are_refused(
    model: AnimeGraphModel, options: dict[str, object], where: str
) -> None:
    with pytest.raises(InvalidRequestError) as caught:
        model.start(SynthesisRequest(fps=FPS, options=options))
    assert caught.value.code == "invalid_request" and caught.value.where == where


def test_forward_joins_are_continuous_and_never_change_a_decided_span(
    model: AnimeGraphModel,
) -> None:
    spans = make_spans(np.random.default_rng(9), 25)
    synthesizer = model.start(fps=FPS, causal=True)
    seen: list[tuple[np.ndarray, np.ndarray]] = []
    for span in spans:
        synthesizer.feed([span])
        synthesizer.frames()
        decided_end = synthesizer.spans[len(synthesizer.nodes) - 1].end
        grid = np.linspace(0.0, decided_end, 200)
        values = synthesizer.track.evaluate(grid, left_continuous=True)
        for earlier_grid, earlier in seen:
            np.testing.assert_array_equal(
                synthesizer.track.evaluate(earlier_grid, left_continuous=True), earlier
            )
        seen = [(grid, values)]
    boundaries = np.array([span.start for span in synthesizer.spans[1:]])
    kinds = {join.kind.value for join in synthesizer.track.joins}
    assert "forward" in kinds  # the search jumped somewhere, so a join was blended
    np.testing.assert_allclose(
        synthesizer.track.evaluate(boundaries),
        synthesizer.track.evaluate(boundaries, left_continuous=True),
        atol=1e-9,
    )


def test_cut_joins_are_where_the_track_jumps(model: AnimeGraphModel) -> None:
    """The continuity check above can fail: without blending a jump is a step."""
    spans = make_spans(np.random.default_rng(9), 25)
    synthesizer = model.start(fps=FPS, causal=True, blend=False)
    synthesizer.feed(spans)
    synthesizer.finish()
    boundaries = np.array([span.start for span in synthesizer.spans[1:]])
    gap = np.abs(
        synthesizer.track.evaluate(boundaries)
        - synthesizer.track.evaluate(boundaries, left_continuous=True)
    )
    assert gap.max() > 1e-3
