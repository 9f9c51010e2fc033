"""Per-phoneme emotion in anime-graph: each run of equal emotion is searched in its own view."""

from __future__ import annotations

import itertools
from typing import TypedDict

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lipstream.audio import Audio
from lipstream.corpus import Corpus
from lipstream.engines.anime_graph import AnimeGraphEngine, AnimeGraphModel
from lipstream.engines.anime_graph.synthesizer import AnimeGraphSynthesizer
from lipstream.engines.base import SynthesisRequest, frames_before
from lipstream.timeline import PhonemeSpan
from tests.lipstream.engines.anime_graph.anime_synthetic import (
    PHONES,
    make_corpus,
    make_spans,
    render_audio,
)


class SearchOptions(TypedDict, total=False):
    """The anime-graph options these tests vary."""

    graph: str
    search: str
    pq_window: int
    pq_advance: int


RECORDED = ("neutral", "happy")  # utterance i of the corpus has RECORDED[i % 2]
OPTION_SETS: list[SearchOptions] = [
    {},
    {"graph": "clustered"},
    {"search": "pq", "pq_window": 3, "pq_advance": 2},
]
FPS = 60.0


@pytest.fixture(scope="module")
def corpus() -> Corpus:
    return make_corpus(seed=5, n_utterances=24, emotions=RECORDED)


@pytest.fixture(scope="module")
def model(corpus: Corpus) -> AnimeGraphModel:
    return AnimeGraphEngine(clusters=30, max_tile=6).fit(corpus)


def tagged(spans: list[PhonemeSpan], emotion: str | None) -> list[PhonemeSpan]:
    return [PhonemeSpan(s.phoneme, s.start, s.end, emotion) for s in spans]


def runs(seed: int, emotions: list[str | None], length: int = 7) -> list[list[PhonemeSpan]]:
    """Consecutive utterance pieces (each between silences), piece i spoken with emotions[i]."""
    rng = np.random.default_rng(seed)
    pieces: list[list[PhonemeSpan]] = []
    for emotion in emotions:
        start = pieces[-1][-1].end if pieces else 0.0
        pieces.append(tagged(make_spans(rng, length, start=start), emotion))
    return pieces


def decided(
    model: AnimeGraphModel,
    spans: list[PhonemeSpan],
    audio: Audio | None = None,
    emotion: str | None = None,
    **options: object,
) -> tuple[AnimeGraphSynthesizer, np.ndarray, np.ndarray]:
    """The finished synthesizer, its frames and the anime shown at each query position."""
    synthesizer = model.start(SynthesisRequest(fps=FPS, emotion=emotion, options=options))
    synthesizer.feed(spans, audio)
    frames = synthesizer.finish()
    animes = np.array([placement.anime for placement in synthesizer.track.placements])
    return synthesizer, frames, animes


def recorded_emotion(model: AnimeGraphModel, animes: np.ndarray) -> list[str]:
    return [RECORDED[int(u) % 2] for u in model.animes.utterance[animes]]


@pytest.mark.parametrize("options", OPTION_SETS)
@pytest.mark.parametrize("request_emotion", [None, "happy", "sad"])
def test_each_run_shows_only_recordings_of_its_emotion(
    model: AnimeGraphModel, options: SearchOptions, request_emotion: str | None
) -> None:
    pieces = runs(3, ["neutral", "happy", None, "sad", "neutral"])
    spans = list(itertools.chain.from_iterable(pieces))
    synthesizer, _, animes = decided(model, spans, emotion=request_emotion, **options)
    spoken = request_emotion or "neutral"  # a request without one gets the default
    fallback = spoken if spoken in RECORDED else "all"
    expected_views = [
        {"neutral": "neutral", "happy": "happy", None: fallback, "sad": "all"}[piece[0].emotion]
        for piece in pieces
        for _ in piece
    ]
    assert [searcher.view.name for searcher in synthesizer.searchers] == expected_views
    shown = recorded_emotion(model, animes)
    for position, view in enumerate(expected_views):
        if view != "all":
            assert shown[position] == view, f"position {position} of the {view} run"
    assert synthesizer.stats["view"] == fallback


@pytest.mark.parametrize("options", OPTION_SETS)
def test_a_change_of_emotion_mid_recording_does_not_continue_that_recording(
    model: AnimeGraphModel, corpus: Corpus, options: SearchOptions
) -> None:
    """The query is a neutral recording, its second half asked for happy: the neutral run
    finds the recording itself, and its natural continuation must not leak into the happy
    run."""
    number = max(
        range(0, len(corpus.utterances), 2), key=lambda index: len(corpus.utterances[index].phones)
    )
    recording = corpus.utterances[number]
    half = len(recording.phones) // 2
    spans = tagged(recording.phones[:half], "neutral") + tagged(recording.phones[half:], "happy")
    synthesizer, _, animes = decided(model, spans, **options)
    assert recorded_emotion(model, animes) == ["neutral"] * half + ["happy"] * (len(spans) - half)
    if not options:  # unclustered greedy: the neutral run is the recording itself
        owner = model.animes.utterance[animes[:half]]
        assert set(owner.tolist()) == {number}


def test_without_match_emotion_every_run_searches_the_whole_corpus(model: AnimeGraphModel) -> None:
    spans = list(itertools.chain.from_iterable(runs(4, ["neutral", "happy"])))
    synthesizer, _, _ = decided(model, spans, match_emotion=False)
    assert {searcher.view.name for searcher in synthesizer.searchers} == {"all"}
    plain = [PhonemeSpan(s.phoneme, s.start, s.end) for s in spans]
    np.testing.assert_array_equal(
        decided(model, spans, match_emotion=False)[1],
        decided(model, plain, emotion="happy", match_emotion=False)[1],
    )


@pytest.mark.parametrize("options", OPTION_SETS)
def test_the_first_run_is_what_its_emotion_alone_gives(
    model: AnimeGraphModel, options: SearchOptions
) -> None:
    first, second = runs(6, ["neutral", "happy"], length=9)
    mixed, mixed_frames, _ = decided(model, first + second, **options)
    alone, alone_frames, _ = decided(model, tagged(first, None), emotion="neutral", **options)
    assert mixed.nodes[: len(first)] == alone.nodes
    # The join into the second run reshapes the first run's last fragment, smoothed H samples.
    settled = first[-1].start - (model.half_width + 1) / model.fps
    count = frames_before(settled, FPS)
    assert count > 20
    np.testing.assert_array_equal(mixed_frames[:count], alone_frames[:count])


@pytest.mark.parametrize("options", OPTION_SETS)
def test_a_later_run_does_not_depend_on_the_run_before(
    model: AnimeGraphModel, options: SearchOptions
) -> None:
    """With audio, joins cost nothing, so a run in a view that holds none of the previous
    run's animes restarts the search: change the phonemes of the neutral run and the happy
    run's fragments, and its frames past the join, stay the same."""
    first, second = runs(8, ["neutral", "happy"], length=9)
    # Same timing, other phonemes (its silences at both ends kept, so the audio around the
    # join is the same noise).
    other = [
        span
        if span.phoneme == "sil"
        else PhonemeSpan(
            PHONES[(PHONES.index(span.phoneme) + 3) % len(PHONES)],
            span.start,
            span.end,
            span.emotion,
        )
        for span in first
    ]
    results = []
    for opening in (first, other):
        spans = opening + second
        audio = render_audio(spans, np.random.default_rng(8))
        results.append(decided(model, spans, audio, **options))
    (one, one_frames, one_animes), (two, two_frames, two_animes) = results
    cut = len(first)
    assert one.nodes[:cut] != two.nodes[:cut]
    assert one.nodes[cut:] == two.nodes[cut:]
    np.testing.assert_array_equal(one_animes[cut:], two_animes[cut:])
    settled = second[1].start + (model.half_width + 1) / model.fps
    start = frames_before(settled, FPS) + 1
    assert len(one_frames) - start > 20
    np.testing.assert_array_equal(one_frames[start:], two_frames[start:])


@pytest.mark.parametrize("search", ["greedy", "pq"])
def test_jumps_count_every_join_that_is_not_a_recorded_succession(
    model: AnimeGraphModel, search: str
) -> None:
    spans = list(itertools.chain.from_iterable(runs(10, ["happy", "neutral", None, "happy"])))
    synthesizer, _, animes = decided(model, spans, search=search, pq_window=3)
    successor = model.poses.successor
    expected = sum(int(successor[left] != right) for left, right in itertools.pairwise(animes))
    assert synthesizer.stats["jumps"] == expected
    assert expected >= 3  # at least the changes of view between disjoint recordings


def test_the_silence_in_a_gap_takes_the_emotion_of_the_span_after_it(
    model: AnimeGraphModel,
) -> None:
    spans = [PhonemeSpan("AA", 0.0, 0.1, "neutral"), PhonemeSpan("M", 0.3, 0.4, "happy")]
    synthesizer, _, animes = decided(model, spans)
    assert [(s.phoneme, s.emotion) for s in synthesizer.spans] == [
        ("AA", "neutral"),
        ("sil", "happy"),
        ("M", "happy"),
    ]
    assert recorded_emotion(model, animes) == ["neutral", "happy", "happy"]


def _stream(
    model: AnimeGraphModel,
    spans: list[PhonemeSpan],
    cuts: list[int],
    audio: Audio | None,
    emotion: str | None,
    options: SearchOptions,
) -> np.ndarray:
    synthesizer = model.start(SynthesisRequest(fps=FPS, emotion=emotion, options=options))
    bounds = [0, *sorted(set(cuts)), len(spans)]
    out = []
    for index, (low, high) in enumerate(itertools.pairwise(bounds)):
        synthesizer.feed(spans[low:high], audio if index == 0 else None)
        out.append(synthesizer.frames())
    out.append(synthesizer.finish())
    return np.concatenate(out)


@settings(max_examples=25, deadline=None)
@given(data=st.data())
def test_mixed_emotions_stream_exactly_like_offline(
    model: AnimeGraphModel, data: st.DataObject
) -> None:
    seed = data.draw(st.integers(0, 2**16))
    emotions = data.draw(
        st.lists(st.sampled_from([None, "neutral", "happy", "sad"]), min_size=1, max_size=4)
    )
    spans = list(itertools.chain.from_iterable(runs(seed, emotions, length=4)))
    # Emotion changes inside pieces too, at arbitrary spans.
    for index in data.draw(st.lists(st.integers(0, len(spans) - 1), max_size=3)):
        spans[index] = PhonemeSpan(
            spans[index].phoneme,
            spans[index].start,
            spans[index].end,
            data.draw(st.sampled_from([None, "neutral", "happy"])),
        )
    audio = render_audio(spans, np.random.default_rng(seed)) if data.draw(st.booleans()) else None
    options: SearchOptions = data.draw(st.sampled_from(OPTION_SETS))
    emotion = data.draw(st.sampled_from([None, "happy"]))
    cuts = data.draw(st.lists(st.integers(1, len(spans) - 1), max_size=10))
    offline = model.synthesize(spans, fps=FPS, audio=audio, emotion=emotion, **options).frames
    np.testing.assert_array_equal(_stream(model, spans, cuts, audio, emotion, options), offline)
