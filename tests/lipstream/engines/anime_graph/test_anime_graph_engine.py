"""The anime-graph engine end to end: streaming, lookahead, storage, stats, views, errors."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lipstream.audio import Audio
from lipstream.engines import get_engine_class, load_model
from lipstream.engines.anime_graph import AnimeGraphEngine, AnimeGraphModel
from lipstream.engines.anime_graph.pq import SearchTimeout
from lipstream.engines.anime_graph.search import count_jumps
from lipstream.engines.base import SynthesisRequest, frames_before
from lipstream.errors import InvalidRequestError, LipstreamError
from lipstream.phonemes import PHONEME_INDEX
from lipstream.timeline import PhonemeSpan
from tests.lipstream.engines.anime_graph.anime_synthetic import (
    SAMPLE_RATE,
    make_corpus,
    make_spans,
    render_audio,
)

OPTION_SETS: list[dict[str, object]] = [
    {},
    {"graph": "clustered"},
    {"search": "pq", "pq_window": 3, "pq_advance": 2},
]


@pytest.fixture(scope="module")
def model() -> AnimeGraphModel:
    corpus = make_corpus(seed=5, n_utterances=24, emotions=("neutral", "happy"))
    return AnimeGraphEngine(clusters=30, max_tile=6).fit(corpus)


def _stream(
    model: AnimeGraphModel,
    spans: list[PhonemeSpan],
    cuts: list[int],
    audio: Audio | None,
    audio_cuts: list[int],
    fps: float,
    emotion: str | None = None,
    **options: object,
) -> np.ndarray:
    """Feed span chunk i with audio piece i; audio pieces left over follow with no spans."""
    synthesizer = model.start(SynthesisRequest(fps=fps, emotion=emotion, options=options))
    bounds = [0, *sorted(set(cuts)), len(spans)]
    pieces: list[Audio | None] = [None] * (len(bounds) - 1)
    if audio is not None:
        edges = [0, *sorted(set(audio_cuts)), len(audio.samples)]
        pieces = [
            Audio(audio.samples[low:high], audio.sample_rate)
            for low, high in itertools.pairwise(edges)
        ]
    out = []
    for step in range(max(len(bounds) - 1, len(pieces))):
        chunk = spans[bounds[step] : bounds[step + 1]] if step < len(bounds) - 1 else []
        synthesizer.feed(chunk, pieces[step] if step < len(pieces) else None)
        out.append(synthesizer.frames())
    out.append(synthesizer.finish())
    return np.concatenate(out)


@settings(max_examples=30, deadline=None)
@given(data=st.data())
def test_any_chunking_gives_the_offline_frames(model: AnimeGraphModel, data: st.DataObject) -> None:
    seed = data.draw(st.integers(0, 2**16))
    spans = make_spans(np.random.default_rng(seed), data.draw(st.integers(2, 20)))
    with_audio = data.draw(st.booleans())
    audio = render_audio(spans, np.random.default_rng(seed)) if with_audio else None
    options = data.draw(st.sampled_from(OPTION_SETS))
    emotion = data.draw(st.sampled_from([None, "happy"]))
    fps = data.draw(st.sampled_from([24.0, 30.0, 60.0, 97.0, 120.0]))
    cuts = data.draw(st.lists(st.integers(1, len(spans) - 1), max_size=8))
    audio_cuts = (
        data.draw(st.lists(st.integers(1, len(audio.samples) - 1), max_size=8))
        if audio is not None
        else []
    )
    offline = model.synthesize(spans, fps=fps, audio=audio, emotion=emotion, **options).frames
    streamed = _stream(model, spans, cuts, audio, audio_cuts, fps, emotion=emotion, **options)
    np.testing.assert_array_equal(streamed, offline)


@pytest.mark.parametrize("options", OPTION_SETS)
def test_frames_come_out_within_the_declared_lookahead(
    model: AnimeGraphModel, options: dict[str, object]
) -> None:
    spans = make_spans(np.random.default_rng(11), 30)
    lookahead = model.lookahead
    synthesizer = model.start(SynthesisRequest(fps=60.0, options=options))
    emitted = 0
    for index, span in enumerate(spans):
        synthesizer.feed([span])
        emitted += len(synthesizer.frames())
        back = index - lookahead.phonemes
        promised = spans[back].end - lookahead.seconds if back >= 0 else 0.0
        assert emitted >= frames_before(promised, 60.0), f"held back at span {index}"
    assert emitted + len(synthesizer.finish()) == len(model.synthesize(spans, fps=60.0).frames)


def test_a_saved_model_answers_exactly_like_the_trained_one(
    model: AnimeGraphModel, tmp_path: Path
) -> None:
    model.save(tmp_path / "ag")
    loaded = load_model(tmp_path / "ag")
    assert isinstance(loaded, AnimeGraphModel)
    rng = np.random.default_rng(2)
    spans = make_spans(rng, 16)
    audio = render_audio(spans, rng)
    for options in OPTION_SETS:
        for sound in (None, audio):
            before = model.synthesize(spans, fps=50.0, audio=sound, emotion="happy", **options)
            after = loaded.synthesize(spans, fps=50.0, audio=sound, emotion="happy", **options)
            np.testing.assert_array_equal(before.frames, after.frames)
            assert before.stats["jumps"] == after.stats["jumps"]


def test_stats_count_the_jumps_and_tiles_of_the_search(model: AnimeGraphModel) -> None:
    spans = make_spans(np.random.default_rng(4), 25)
    synthesizer = model.start(fps=60.0)
    synthesizer.feed(spans)
    synthesizer.finish()
    stats = synthesizer.stats
    assert stats["jumps"] == count_jumps(synthesizer.graph, np.array(synthesizer.nodes))
    assert stats["tiles"] >= stats["jumps"] + 1
    assert stats["search_ms"] > 0.0
    assert stats["frames"] == len(model.synthesize(spans, fps=60.0).frames)


def test_greedy_reaches_the_fewest_jumps_of_any_matching(model: AnimeGraphModel) -> None:
    spans = make_spans(np.random.default_rng(9), 14)
    synthesizer = model.start(fps=60.0, max_tile=0)
    synthesizer.feed(spans)
    synthesizer.finish()
    graph, query = synthesizer.graph, synthesizer.query
    best = {int(node): 0 for node in graph.nodes_with_label(query[0])}
    for label in query[1:]:
        best = {
            int(node): min(
                jumps + int(not graph.is_edge(np.array([previous]), np.array([node]))[0])
                for previous, jumps in best.items()
            )
            for node in graph.nodes_with_label(label)
        }
    assert synthesizer.stats["jumps"] == min(best.values()) == synthesizer.stats["tiles"] - 1


def test_an_emotion_is_searched_among_its_own_recordings(model: AnimeGraphModel) -> None:
    spans = make_spans(np.random.default_rng(6), 20)
    recorded_emotion = ["neutral", "happy"]
    for emotion, view in [
        ("happy", "happy"),
        ("neutral", "neutral"),
        (None, "neutral"),  # the default emotion
        ("sad", "all"),
    ]:
        synthesizer = model.start(fps=60.0, emotion=emotion)
        synthesizer.feed(spans)
        synthesizer.finish()
        assert synthesizer.stats["view"] == view
        if view != "all":
            utterances = model.animes.utterance[np.array(synthesizer.nodes)]
            assert {recorded_emotion[int(u) % 2] for u in utterances} == {view}
    unmatched = model.start(fps=60.0, emotion="happy", match_emotion=False)
    assert unmatched.view.name == "all"


def test_a_phoneme_the_corpus_never_says_borrows_its_viseme(model: AnimeGraphModel) -> None:
    spans = [
        PhonemeSpan("sil", 0.0, 0.1),
        PhonemeSpan("P", 0.1, 0.2),
        PhonemeSpan("AA", 0.2, 0.3),
        PhonemeSpan("ZH", 0.3, 0.4),
    ]
    synthesizer = model.start(fps=60.0)
    synthesizer.feed(spans)
    frames = synthesizer.finish()
    assert frames.shape == (25, 6) and np.all(np.isfinite(frames))
    labels = model.animes.labels[np.array(synthesizer.nodes)]
    assert labels[1] in (PHONEME_INDEX["B"], PHONEME_INDEX["M"])
    assert labels[3] in (PHONEME_INDEX["S"], PHONEME_INDEX["sil"])


@pytest.mark.parametrize(
    "options, where",
    [
        ({"graph": "tree"}, "options.graph"),
        ({"search": "astar"}, "options.search"),
        ({"pq_window": 9}, "options.pq_window"),
        ({"pq_window": 3, "pq_advance": 4}, "options.pq_advance"),
        ({"blend": "yes"}, "options.blend"),
        ({"speed": 2}, "options.speed"),
        ({"max_tile": -1}, "options.max_tile"),
        ({"pq_budget_s": 0}, "options.pq_budget_s"),
    ],
)
def test_bad_options_are_refused(
    model: AnimeGraphModel, options: dict[str, object], where: str
) -> None:
    with pytest.raises(InvalidRequestError) as caught:
        model.start(SynthesisRequest(fps=60.0, options=options))
    assert caught.value.where == where


def test_a_pq_request_gives_up_after_its_budget(model: AnimeGraphModel) -> None:
    spans = make_spans(np.random.default_rng(8), 12)
    with pytest.raises(SearchTimeout) as caught:
        model.synthesize(spans, search="pq", pq_window=2, pq_budget_s=1e-9)
    assert caught.value.code == "search_timeout"
    finished = model.synthesize(spans, search="pq", pq_window=2, pq_budget_s=60.0)
    assert finished.stats["search"] == "pq" and finished.stats["frames"] > 0


def test_audio_must_start_with_the_request(model: AnimeGraphModel) -> None:
    spans = make_spans(np.random.default_rng(1), 4)
    audio = render_audio(spans, np.random.default_rng(1))
    synthesizer = model.start(fps=60.0)
    synthesizer.feed(spans[:2])
    with pytest.raises(InvalidRequestError) as caught:
        synthesizer.feed(spans[2:], audio)
    assert caught.value.where == "audio"
    mixed = model.start(fps=60.0)
    mixed.feed(spans[:2], audio)
    with pytest.raises(InvalidRequestError):
        mixed.feed(spans[2:], Audio(audio.samples, SAMPLE_RATE // 2))


def test_hyperparameters_are_checked_and_registered() -> None:
    assert get_engine_class("anime-graph") is AnimeGraphEngine
    with pytest.raises(LipstreamError) as caught:
        AnimeGraphEngine(variance=1.5)
    assert caught.value.where == "anime-graph.variance"
    with pytest.raises(LipstreamError):
        AnimeGraphEngine(graph="clustered", clusters=0)
    with pytest.raises(LipstreamError):
        AnimeGraphEngine(max_tile=0)


def test_a_model_without_clusters_refuses_the_clustered_graph() -> None:
    lean = AnimeGraphEngine(clusters=0).fit(make_corpus(seed=2, n_utterances=4, with_audio=False))
    assert lean.manifest.extra["audio_features"] is False
    with pytest.raises(InvalidRequestError):
        lean.start(fps=60.0, graph="clustered")
    frames = lean.synthesize(make_spans(np.random.default_rng(0), 5), fps=30.0).frames
    assert frames.dtype == np.float32 and np.all(np.isfinite(frames))


def test_render_samples_the_offline_track_and_empty_input_gives_no_frames(
    model: AnimeGraphModel,
) -> None:
    spans = make_spans(np.random.default_rng(12), 8)
    offline = model.synthesize(spans, fps=model.fps).frames
    times = np.arange(len(offline)) / model.fps
    request = SynthesisRequest(fps=30.0)
    np.testing.assert_allclose(model.render(spans, times, request, None), offline, atol=1e-6)
    synthesizer = model.start(fps=30.0)
    assert synthesizer.finish().shape == (0, 6)


@pytest.mark.parametrize(("window", "allowed"), [(6, 42), (4, 64), (1, 256)])
def test_pq_takes_at_most_256_window_phonemes(
    model: AnimeGraphModel, window: int, allowed: int
) -> None:
    synthesizer = model.start(fps=60, search="pq", pq_window=window)
    spans = [("AA", 0.08 * i, 0.08 * (i + 1)) for i in range(allowed + 1)]
    synthesizer.feed(spans[:allowed])  # at the cap: accepted (feeding searches nothing)
    with pytest.raises(LipstreamError) as raised:
        synthesizer.feed(spans[allowed:])
    assert (raised.value.code, raised.value.where) == ("search_too_large", "options.search")
    greedy = model.start(fps=60)
    greedy.feed(spans)  # the cap is PQ's only


def test_a_long_request_holds_a_window_of_samples_not_its_utterance(
    model: AnimeGraphModel,
) -> None:
    spans = [
        PhonemeSpan(("AA", "M", "S", "IY")[i % 4], i * 0.08, (i + 1) * 0.08) for i in range(600)
    ]
    synthesizer = model.start(fps=1000.0)
    frames = 0
    held: list[int] = []
    for span in spans:
        synthesizer.feed([span])
        frames += len(synthesizer.frames())
        held.append(len(synthesizer.raw.data) + len(synthesizer.smoothed.data))
    frames += len(synthesizer.finish())
    assert frames == 48_001  # 48 s at 1000 fps
    # 48 s at the model's rate are thousands of samples; the buffers stay at a window.
    samples = 48 * model.fps
    assert samples > 5000
    assert max(held) < samples / 20
