"""Viseme events beside word timings (Azure, Polly) anchor the onsets of the phonemes
inside words: by hand-worked examples, by a brute-force longest common subsequence, and
against espeak-ng's own phoneme events, closer than the words alone."""

from __future__ import annotations

import itertools
import json
import random
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from lipstream.bench import tts_shapes
from lipstream.frontends.formats import parse_timings
from lipstream.frontends.viseme_anchors import paired
from lipstream.frontends.word_durations import WordDurationModel
from lipstream.frontends.words_to_spans import timings_to_spans
from lipstream.speech.spoken_words import SpokenUtterance
from lipstream.timeline import PhonemeSpan

SHAPES: dict[str, Callable[[SpokenUtterance], Any]] = {
    "azure": tts_shapes.azure_input,
    "polly": tts_shapes.polly_input,
}


def _rounded(spans: list[PhonemeSpan]) -> list[tuple[str, float, float]]:
    """Each span to the nanosecond: ticks and ms become seconds by a float product."""
    return [(span.phoneme, round(span.start, 9), round(span.end, 9)) for span in spans]


def _common_length(first: str, second: str) -> int:
    """The longest common subsequence's length, by trying every subsequence of ``first``."""
    for size in range(len(first), 0, -1):
        for kept in itertools.combinations(first, size):
            rest = iter(second)
            if all(label in rest for label in kept):
                return size
    return 0


def test_pairs_are_a_longest_common_subsequence() -> None:
    draw = random.Random(25)
    for _ in range(200):
        first = "".join(draw.choice("abc") for _ in range(draw.randint(0, 7)))
        second = "".join(draw.choice("abc") for _ in range(draw.randint(0, 7)))
        pairs = paired(list(first), list(second))
        assert len(pairs) == _common_length(first, second)
        assert all(first[i] == second[j] for i, j in pairs)
        assert all(a[0] < b[0] and a[1] < b[1] for a, b in zip(pairs, pairs[1:]))


def test_azure_visemes_place_each_phoneme_of_a_word_where_its_viseme_starts(
    espeak_durations: WordDurationModel,
) -> None:
    # "map" = M AE P over [0.1, 0.4] s; visemes 21 (p b m), 1 (æ ə ʌ), 21 at 0.1, 0.16, 0.31.
    events = [
        {"audioOffset": 1_000_000, "duration": 3_000_000, "text": "map", "wordLength": 3},
        {"audioOffset": 1_000_000, "visemeId": 21},
        {"audioOffset": 1_600_000, "visemeId": 1},
        {"audioOffset": 3_100_000, "visemeId": 21},
    ]
    spans = timings_to_spans(parse_timings(events), espeak_durations)
    assert _rounded(spans) == [
        ("sil", 0.0, 0.1),
        ("M", 0.1, 0.16),
        ("AE", 0.16, 0.31),
        ("P", 0.31, 0.4),
    ]


def test_polly_visemes_place_phonemes_and_sil_ends_the_word(
    espeak_durations: WordDurationModel,
) -> None:
    # "bay" = B EY from 100 ms; visemes p, e; sil at 420 ms ends it.
    marks = [
        {"time": 100, "type": "word", "start": 0, "end": 3, "value": "bay"},
        {"time": 100, "type": "viseme", "value": "p"},
        {"time": 190, "type": "viseme", "value": "e"},
        {"time": 420, "type": "viseme", "value": "sil"},
    ]
    lines = "\n".join(json.dumps(mark) for mark in marks)
    spans = timings_to_spans(parse_timings(lines), espeak_durations)
    assert _rounded(spans) == [("sil", 0.0, 0.1), ("B", 0.1, 0.19), ("EY", 0.19, 0.42)]


def test_a_viseme_that_does_not_pair_leaves_the_onset_to_the_duration_model(
    espeak_durations: WordDurationModel,
) -> None:
    words = [{"word": "map", "start": 0.1, "end": 0.4}]
    by_words = timings_to_spans(parse_timings(words, "words"), espeak_durations)
    events = [
        {"audioOffset": 1_000_000, "duration": 3_000_000, "text": "map", "wordLength": 3},
        {"audioOffset": 1_000_000, "visemeId": 21},
        {"audioOffset": 2_000_000, "visemeId": 16},  # ʃ: said in no phoneme of "map"
    ]
    by_events = timings_to_spans(parse_timings(events), espeak_durations)
    assert _rounded(by_events) == _rounded(by_words)


@pytest.mark.parametrize("format", ["azure", "polly"])
def test_visemes_beside_words_bring_onsets_closer_than_words_alone(
    format: str,
    espeak_spoken: tuple[list[SpokenUtterance], list[SpokenUtterance]],
    espeak_durations: WordDurationModel,
) -> None:
    with_visemes: list[float] = []
    words_alone: list[float] = []
    for utterance in espeak_spoken[1]:
        sent = SHAPES[format](utterance)
        spans = timings_to_spans(parse_timings(sent, format), espeak_durations)
        with_visemes += tts_shapes.onset_errors(utterance.words, spans)
        plain = tts_shapes.words_input(utterance)
        spans = timings_to_spans(parse_timings(plain, "words"), espeak_durations)
        words_alone += tts_shapes.onset_errors(utterance.words, spans)
    anchored_ms = np.array(with_visemes) * 1000
    plain_ms = np.array(words_alone) * 1000
    # The visemes carry espeak-ng's onsets rounded to 0.1 µs (Azure) or 1 ms (Polly).
    assert np.median(anchored_ms) <= 1.0
    assert np.percentile(anchored_ms, 75) <= 1.0
    assert np.percentile(plain_ms, 75) > 5.0
    assert len(anchored_ms) == len(plain_ms)
