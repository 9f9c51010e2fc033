"""TTS timings of espeak-ng's own speech, in each provider's shape, to phoneme spans: the
derived onsets land near espeak-ng's true phoneme events; viseme and phoneme inputs keep
their times exactly."""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from lipstream.bench import tts_shapes
from lipstream.frontends.formats import parse_timings
from lipstream.frontends.word_durations import WordDurationModel
from lipstream.frontends.words_to_spans import timings_to_spans
from lipstream.speech.spoken_words import SpokenUtterance

WORD_TIMING_MEDIAN_MS = 20.0
WORD_TIMING_P90_MS = 60.0
CHARACTER_TIMING_INNER_MEDIAN_MS = 10.0

BUILDERS: dict[str, Callable[[SpokenUtterance], Any]] = {
    "words": tts_shapes.words_input,
    "elevenlabs": tts_shapes.elevenlabs_input,
    "azure": tts_shapes.azure_input,
    "polly": tts_shapes.polly_input,
}


@pytest.mark.parametrize("format", list(BUILDERS))
def test_word_and_character_timings_give_onsets_near_espeaks_own(
    format: str,
    espeak_spoken: tuple[list[SpokenUtterance], list[SpokenUtterance]],
    espeak_durations: WordDurationModel,
) -> None:
    errors: list[float] = []
    compared = 0
    for utterance in espeak_spoken[1]:
        sent = BUILDERS[format](utterance)
        wire = sent if isinstance(sent, str) else json.dumps(sent)  # as a file holds it
        timings = parse_timings(wire)
        assert timings.format == format
        spans = timings_to_spans(timings, espeak_durations)
        assert spans[0].start == 0.0 and all(a.end == b.start for a, b in zip(spans, spans[1:]))
        errors += tts_shapes.onset_errors(utterance.words, spans)
        compared += sum(len(word.phonemes) for word in utterance.words)
    errors_ms = np.array(errors) * 1000
    assert len(errors_ms) > 0.8 * compared  # the lexicon agrees with espeak-ng on most phonemes
    assert np.median(errors_ms) <= WORD_TIMING_MEDIAN_MS
    assert np.percentile(errors_ms, 90) <= WORD_TIMING_P90_MS


def test_ipa_phoneme_timestamps_keep_espeaks_onsets(
    espeak_spoken: tuple[list[SpokenUtterance], list[SpokenUtterance]],
    espeak_durations: WordDurationModel,
) -> None:
    for utterance in espeak_spoken[1][:5]:
        spans = timings_to_spans(
            parse_timings(json.dumps(tts_shapes.ipa_input(utterance))), espeak_durations
        )
        derived = [(s.phoneme, s.start) for s in spans if s.phoneme != "sil"]
        truth = [(s.phoneme, round(s.start, 3)) for s in utterance.spans if s.phoneme != "sil"]
        assert derived == truth


@pytest.mark.parametrize(
    ("build", "table"),
    [
        (tts_shapes.azure_visemes, tts_shapes.AZURE_VISEME_OF),
        (lambda u: tts_shapes.polly_input(u, words=False), tts_shapes.POLLY_VISEME_OF),
    ],
)
def test_visemes_alone_become_spans_starting_at_each_viseme(
    build: Callable[[SpokenUtterance], Any],
    table: dict[str, Any],
    espeak_spoken: tuple[list[SpokenUtterance], list[SpokenUtterance]],
    espeak_durations: WordDurationModel,
) -> None:
    utterance = espeak_spoken[1][0]
    sent = build(utterance)
    spans = timings_to_spans(
        parse_timings(sent if isinstance(sent, str) else json.dumps(sent)), espeak_durations
    )
    # Where the viseme changes, a span starts, and it belongs to that viseme's class.
    changes = [
        (span.start, table[span.phoneme])
        for previous, span in zip(utterance.spans, utterance.spans[1:])
        if table[span.phoneme] != table[previous.phoneme]
    ]
    derived = {round(span.start, 3): table[span.phoneme] for span in spans}
    for start, viseme in changes:
        assert derived.get(round(start, 3)) == viseme, (start, viseme)


def test_a_polly_word_left_open_ends_by_the_duration_model(
    espeak_durations: WordDurationModel,
) -> None:
    marks = '{"time":100,"type":"word","start":0,"end":4,"value":"hello"}\n'
    spans = timings_to_spans(parse_timings(marks), espeak_durations)
    assert [s.phoneme for s in spans] == ["sil", "HH", "AH", "L", "OW"]
    expected = sum(np.exp(espeak_durations.log_mean_[i]) for i in (15, 2, 20, 24))
    assert spans[-1].end == pytest.approx(0.1 + expected)


def test_timings_that_say_nothing_are_empty_timings(espeak_durations: WordDurationModel) -> None:
    from lipstream.errors import LipstreamError

    with pytest.raises(LipstreamError) as caught:
        timings_to_spans(parse_timings([{"word": "—", "start": 0.0, "end": 0.3}]), espeak_durations)
    assert caught.value.code == "empty_timings"


def test_character_timings_place_onsets_inside_words_within_10_ms(
    espeak_spoken: tuple[list[SpokenUtterance], list[SpokenUtterance]],
    espeak_durations: WordDurationModel,
) -> None:
    inner: dict[str, list[float]] = {"elevenlabs": [], "words": []}
    for utterance in espeak_spoken[1]:
        for format in inner:
            timings = parse_timings(json.dumps(BUILDERS[format](utterance)))
            spans = timings_to_spans(timings, espeak_durations)
            inner[format] += tts_shapes.onset_errors(utterance.words, spans, inner=True)
    characters_ms, words_ms = (np.array(inner[name]) * 1000 for name in ("elevenlabs", "words"))
    assert len(characters_ms) > 300
    assert np.median(characters_ms) <= CHARACTER_TIMING_INNER_MEDIAN_MS
    assert np.median(characters_ms) < np.median(words_ms)
    assert np.percentile(characters_ms, 90) < np.percentile(words_ms, 90)
