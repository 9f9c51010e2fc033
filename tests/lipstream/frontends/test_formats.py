"""Every timing format parsed from a real example, detected from its content, and every
kind of bad input refused with a coded error naming the place."""

from __future__ import annotations

import json
import math
from typing import Any

import pytest

from lipstream.errors import LipstreamError
from lipstream.frontends.formats import detect_format, parse_timings, read_timing_text

# The shapes below are as the providers document them (see docs/how-to/tts-timings.md).
ELEVENLABS = {
    "audio_base64": "",
    "alignment": {
        "characters": ["H", "i", " ", "t", "h", "e", "r", "e", "!"],
        "character_start_times_seconds": [
            0.0,
            0.116,
            0.186,
            0.232,
            0.279,
            0.325,
            0.371,
            0.418,
            0.464,
        ],
        "character_end_times_seconds": [
            0.116,
            0.186,
            0.232,
            0.279,
            0.325,
            0.371,
            0.418,
            0.464,
            0.557,
        ],
    },
}
AZURE: list[dict[str, int | str]] = [
    {
        "audioOffset": 500000,
        "duration": 3125000,
        "text": "Hello",
        "textOffset": 0,
        "wordLength": 5,
        "boundaryType": "WordBoundary",
    },
    {
        "audioOffset": 3625000,
        "duration": 0,
        "text": ",",
        "textOffset": 5,
        "wordLength": 1,
        "boundaryType": "PunctuationBoundary",
    },
    {
        "audioOffset": 5000000,
        "duration": 4000000,
        "text": "world",
        "textOffset": 7,
        "wordLength": 5,
        "boundaryType": "WordBoundary",
    },
    {"audioOffset": 500000, "visemeId": 12},
]
POLLY = (
    '{"time":6,"type":"sentence","start":0,"end":23,"value":"Mary had a little lamb."}\n'
    '{"time":6,"type":"word","start":0,"end":4,"value":"Mary"}\n'
    '{"time":6,"type":"viseme","value":"p"}\n'
    '{"time":73,"type":"viseme","value":"E"}\n'
    '{"time":180,"type":"viseme","value":"r"}\n'
    '{"time":292,"type":"viseme","value":"i"}\n'
    '{"time":373,"type":"word","start":5,"end":8,"value":"had"}\n'
    '{"time":373,"type":"viseme","value":"k"}\n'
    '{"time":460,"type":"viseme","value":"a"}\n'
    '{"time":521,"type":"viseme","value":"t"}\n'
    '{"time":620,"type":"viseme","value":"sil"}\n'
)
CARTESIA = {
    "type": "phoneme_timestamps",
    "done": False,
    "phoneme_timestamps": {
        "phonemes": ["h", "ə", "l", "oʊ"],
        "start": [0.093, 0.174, 0.255, 0.337],
        "end": [0.174, 0.255, 0.337, 0.418],
    },
}
HUME = [
    {
        "type": "timestamp",
        "timestamp": {"type": "word", "text": "Hi", "time": {"begin": 0, "end": 240}},
    },
    {
        "type": "timestamp",
        "timestamp": {"type": "phoneme", "text": "h", "time": {"begin": 0, "end": 90}},
    },
    {
        "type": "timestamp",
        "timestamp": {"type": "phoneme", "text": "aɪ", "time": {"begin": 90, "end": 240}},
    },
]
WORDS = [{"word": "Hello", "start": 0.05, "end": 0.36}, {"word": "world", "start": 0.5, "end": 0.9}]


def test_elevenlabs_characters_become_words_with_their_characters() -> None:
    timings = parse_timings(ELEVENLABS)
    assert timings.format == "elevenlabs"
    assert [(w.text, w.start, w.end) for w in timings.words] == [
        ("Hi", 0.0, 0.186),
        ("there!", 0.232, 0.557),
    ]
    assert [c.char for c in timings.words[1].characters] == list("there!")
    assert timings.words[1].characters[2].start == 0.325


def test_elevenlabs_prefers_the_normalized_alignment_and_reads_streamed_chunks() -> None:
    normalized = {
        "characters": list("four"),
        "character_start_times_seconds": [0.0, 0.1, 0.2, 0.3],
        "character_end_times_seconds": [0.1, 0.2, 0.3, 0.4],
    }
    later = {
        "characters": list(" it"),
        "character_start_times_seconds": [0.4, 0.5, 0.6],
        "character_end_times_seconds": [0.5, 0.6, 0.7],
    }
    chunks = [
        {
            "alignment": {**normalized, "characters": list("4") + ["", "", ""]},
            "normalized_alignment": normalized,
        },
        {"alignment": later},
    ]
    assert [(w.text, w.start, w.end) for w in parse_timings(chunks).words] == [
        ("four", 0.0, 0.4),
        ("it", 0.5, 0.7),
    ]


def test_azure_word_boundaries_in_ticks_skip_punctuation_and_keep_words() -> None:
    timings = parse_timings(AZURE)
    assert [(w.text, round(w.start, 9), round(w.end or 0, 9)) for w in timings.words] == [
        ("Hello", 0.05, 0.3625),
        ("world", 0.5, 0.9),
    ]
    # The viseme event is Hello's, and kept beside the words too (for a stream's later
    # chunks to join).
    assert [[v.viseme for v in w.visemes] for w in timings.words] == [["12"], []]
    assert [(v.viseme, v.where) for v in timings.visemes] == [("12", "events[3]")]


def test_azure_visemes_alone_are_read_by_id() -> None:
    timings = parse_timings(
        [{"audioOffset": 0, "visemeId": 0}, {"audioOffset": 1250000, "visemeId": 21}]
    )
    assert [(v.viseme, v.start) for v in timings.visemes] == [("0", 0.0), ("21", 0.125)]


def test_polly_word_marks_end_at_the_next_word_or_a_silence() -> None:
    timings = parse_timings(POLLY)
    assert [(w.text, w.start, w.end) for w in timings.words] == [
        ("Mary", 0.006, 0.373),
        ("had", 0.373, 0.62),
    ]


def test_polly_last_word_without_a_silence_is_left_open() -> None:
    marks = '{"time":10,"type":"word","start":0,"end":2,"value":"Hi"}'
    assert parse_timings(marks).words[0].end is None


def test_cartesia_and_hume_ipa_phonemes_map_to_the_phoneme_set() -> None:
    spans = parse_timings(CARTESIA).phonemes
    assert [(s.phoneme, s.start, s.end) for s in spans] == [
        ("HH", 0.093, 0.174),
        ("AH", 0.174, 0.255),
        ("L", 0.255, 0.337),
        ("OW", 0.337, 0.418),
    ]
    hume = parse_timings(HUME).phonemes
    assert [(s.phoneme, s.start, s.end) for s in hume] == [("HH", 0.0, 0.09), ("AY", 0.09, 0.24)]


def test_generic_words_as_objects_or_parallel_arrays() -> None:
    listed = parse_timings(WORDS)
    parallel = parse_timings(
        {"word_timestamps": {"words": ["Hello", "world"], "start": [0.05, 0.5], "end": [0.36, 0.9]}}
    )
    expected = [("Hello", 0.05, 0.36), ("world", 0.5, 0.9)]
    assert [(w.text, w.start, w.end) for w in listed.words] == expected
    assert [(w.text, w.start, w.end) for w in parallel.words] == expected


@pytest.mark.parametrize(
    ("data", "expected"),
    [
        (ELEVENLABS, "elevenlabs"),
        (AZURE, "azure"),
        (read_timing_text(POLLY), "polly"),
        (CARTESIA, "ipa"),
        (HUME, "ipa"),
        (WORDS, "words"),
        ({"words": WORDS}, "words"),
    ],
)
def test_each_format_is_detected_from_its_content(data: Any, expected: str) -> None:
    assert detect_format(data) == expected


def _error(data: Any, format: str = "auto") -> LipstreamError:
    with pytest.raises(LipstreamError) as caught:
        parse_timings(data, format)
    return caught.value


def _words(*items: tuple[str, float, float]) -> list[dict[str, Any]]:
    return [{"word": w, "start": s, "end": e} for w, s, e in items]


@pytest.mark.parametrize(
    ("data", "code", "where"),
    [
        (_words(("a", 0.5, 0.7), ("b", 0.2, 0.4)), "non_monotonic_times", "words[1]"),
        (_words(("a", 0.0, 0.5), ("b", 0.3, 0.8)), "non_monotonic_times", "words[1]"),
        (_words(("a", -0.1, 0.5)), "invalid_times", "words[0].start"),
        (_words(("a", 0.0, math.nan)), "invalid_times", "words[0].end"),
        (_words(("a", 0.4, 0.2)), "invalid_times", "words[0]"),
        ([{"word": "a", "start": "0", "end": 1}], "invalid_times", "words[0].start"),
        ({"words": []}, "empty_timings", "words"),
        ([], "empty_timings", "input"),
        ("", "empty_timings", "input"),
        ({"foo": 1}, "unknown_timing_format", "input"),
        ("{not json", "unknown_timing_format", "input:line 1"),
    ],
)
def test_bad_word_lists_get_coded_errors_naming_the_place(data: Any, code: str, where: str) -> None:
    error = _error(data)
    assert (error.code, error.where) == (code, where), error


def test_characters_that_do_not_match_their_times_are_refused() -> None:
    short = json.loads(json.dumps(ELEVENLABS))
    short["alignment"]["character_end_times_seconds"].pop()
    error = _error(short)
    assert (error.code, error.where) == ("mismatched_words", "alignment")
    double = json.loads(json.dumps(ELEVENLABS))
    double["alignment"]["characters"][1] = "ii"
    error = _error(double)
    assert (error.code, error.where) == ("mismatched_words", "alignment.characters[1]")


def test_an_azure_word_length_other_than_its_text_is_refused() -> None:
    event = dict(AZURE[0], wordLength=7)
    error = _error([event])
    assert (error.code, error.where) == ("mismatched_words", "events[0].wordLength")


def test_overlapping_characters_and_nan_ticks_are_refused() -> None:
    overlapping = json.loads(json.dumps(ELEVENLABS))
    overlapping["alignment"]["character_start_times_seconds"][4] = 0.2
    error = _error(overlapping)
    assert (error.code, error.where) == ("non_monotonic_times", "alignment.characters[4]")
    error = _error([{"audioOffset": math.nan, "text": "a"}], "azure")
    assert (error.code, error.where) == ("invalid_times", "events[0].audioOffset")


def test_a_named_format_that_does_not_fit_says_where() -> None:
    error = _error(WORDS, "polly")
    assert (error.code, error.where) == ("unknown_timing_format", "marks[0]")
    error = _error(WORDS, "klingon")
    assert (error.code, error.where) == ("unknown_timing_format", "format")


def test_an_unknown_ipa_phoneme_names_it() -> None:
    error = _error({"phonemes": ["h", "☃"], "start": [0.0, 0.1], "end": [0.1, 0.2]})
    assert (error.code, error.where) == ("unknown_phoneme", "phonemes[1]")


def test_elevenlabs_websocket_chunks_in_ms_with_durations() -> None:
    chunk: dict[str, Any] = {
        "audio": "",
        "isFinal": None,
        "normalizedAlignment": {
            "chars": ["H", "i", " ", "y", "o", "u"],
            "charStartTimesMs": [0, 116, 186, 232, 279, 325],
            "charDurationsMs": [116, 70, 46, 47, 46, 93],
        },
    }
    timings = parse_timings(chunk)
    assert timings.format == "elevenlabs"
    assert [(w.text, w.start, w.end) for w in timings.words] == [
        ("Hi", 0.0, 0.186),
        ("you", 0.232, pytest.approx(0.418)),
    ]
    chunk["normalizedAlignment"]["charDurationsMs"][1] = -5
    error = _error(chunk)
    assert (error.code, error.where) == ("invalid_times", "normalizedAlignment.charDurationsMs[1]")


def test_azure_words_without_duration_end_at_the_next_word_and_the_last_stays_open() -> None:
    events = [
        {"audioOffset": 1_000_000, "text": "one"},
        {"audioOffset": 4_000_000, "text": "two"},
    ]
    timings = parse_timings(events)
    assert [(w.text, w.end) for w in timings.words] == [("one", pytest.approx(0.4)), ("two", None)]
    assert timings.last_word_open
