"""Word timings in a language other than English: German sentences spoken by espeak-ng,
their words written as a TTS's word list, get their phonemes from espeak-ng with the
request's voice (read as IPA through the feature table) and land near espeak-ng's own
phoneme events."""

from __future__ import annotations

import json

import numpy as np
import pytest

from lipstream.bench import tts_shapes
from lipstream.frontends.formats import parse_timings
from lipstream.frontends.lexicon import pronounce
from lipstream.frontends.word_durations import WordDurationModel
from lipstream.frontends.words_to_spans import timings_to_spans
from lipstream.speech.spoken_words import SpokenUtterance, speak_words

GERMAN = (
    "Über die Brücke fahren schöne Züge.",
    "Der Hund schläft unter dem großen Tisch.",
    "Morgen besuchen wir meine Großmutter in Hamburg.",
    "Im Sommer ist das Wasser im See warm.",
    "Bitte schließen Sie das Fenster, es regnet.",
    "Die Kinder spielen im Garten mit dem Ball.",
)
WORD_TIMING_MEDIAN_MS = 20.0
WORD_TIMING_P90_MS = 60.0


@pytest.fixture(scope="module")
def german(espeak_spoken: object) -> list[SpokenUtterance]:  # espeak_spoken: skips without it
    return speak_words(GERMAN, voice="de")


def test_german_words_are_pronounced_as_espeak_ng_speaks_them(
    german: list[SpokenUtterance],
) -> None:
    for utterance in german:
        truth = [
            tuple(p.phoneme for p in word.phonemes if p.phoneme != "sil")
            for word in utterance.words
        ]
        assert pronounce([word.text for word in utterance.words], "de") == truth


def test_german_word_timings_give_onsets_near_espeaks_own(
    german: list[SpokenUtterance], espeak_durations: WordDurationModel
) -> None:
    errors: list[float] = []
    compared = 0
    for utterance in german:
        timings = parse_timings(json.dumps(tts_shapes.words_input(utterance)))
        spans = timings_to_spans(timings, espeak_durations, voice="de")
        assert spans[0].start == 0.0 and all(a.end == b.start for a, b in zip(spans, spans[1:]))
        errors += tts_shapes.onset_errors(utterance.words, spans)
        compared += sum(len(word.phonemes) for word in utterance.words)
    errors_ms = np.array(errors) * 1000
    assert len(errors_ms) > 0.8 * compared
    assert np.median(errors_ms) <= WORD_TIMING_MEDIAN_MS
    assert np.percentile(errors_ms, 90) <= WORD_TIMING_P90_MS
