"""Timings in chunks: a word cut at a chunk's edge is held and joined, a Polly word's end
comes from the next word, and whatever is held is released at the end; an Azure or Polly
word waits for its visemes in later chunks, and a viseme after its word was released is
``non_monotonic_times``."""

from __future__ import annotations

import pytest

from lipstream.errors import LipstreamError
from lipstream.frontends.formats import parse_timings
from lipstream.frontends.timings import SpeechTimings
from lipstream.frontends.word_stream import WordStream


def _chars(text: str, start: float, step: float = 0.1) -> dict[str, object]:
    return {
        "characters": list(text),
        "character_start_times_seconds": [round(start + i * step, 3) for i in range(len(text))],
        "character_end_times_seconds": [round(start + (i + 1) * step, 3) for i in range(len(text))],
    }


def _words(chunks: list[list[SpeechTimings]]) -> list[tuple[str, float, float | None]]:
    return [(w.text, w.start, w.end) for chunk in chunks for t in chunk for w in t.words]


def test_a_word_cut_between_character_chunks_is_joined() -> None:
    stream = WordStream()
    first = stream.take(parse_timings({"alignment": _chars("Hello wo", 0.0)}))
    second = stream.take(parse_timings({"alignment": _chars("rld again", 0.8)}))
    last = stream.finish()
    assert _words([first]) == [("Hello", 0.0, 0.5)]
    assert _words([second]) == [("world", 0.6, 1.1)]
    assert _words([last]) == [("again", 1.2, 1.7)]


def test_a_chunk_ending_in_white_space_holds_nothing() -> None:
    stream = WordStream()
    first = stream.take(parse_timings({"alignment": _chars("Hi there ", 0.0)}))
    assert _words([first]) == [("Hi", 0.0, 0.2), ("there", 0.3, 0.8)]
    assert stream.finish() == []
    second = stream.take(parse_timings({"alignment": _chars("you", 0.9)}))
    assert second == []  # "you" may go on
    assert _words([stream.finish()]) == [("you", 0.9, 1.2)]


def test_a_polly_word_ends_where_the_next_chunk_s_first_word_starts() -> None:
    stream = WordStream()
    first = stream.take(
        parse_timings('{"time":100,"type":"word","start":0,"end":4,"value":"Mary"}')
    )
    assert first == []
    second = stream.take(
        parse_timings('{"time":480,"type":"word","start":5,"end":8,"value":"had"}')
    )
    assert _words([second]) == [("Mary", 0.1, 0.48)]
    assert _words([stream.finish()]) == [("had", 0.48, None)]


def test_phonemes_release_a_held_word_first() -> None:
    stream = WordStream()
    stream.take(parse_timings({"alignment": _chars("yes", 0.0)}))
    out = stream.take(parse_timings({"phonemes": ["m"], "start": [0.5], "end": [0.6]}))
    assert [t.format for t in out] == ["elevenlabs", "ipa"]
    assert _words([out[:1]]) == [("yes", 0.0, 0.3)]


def _azure_word(text: str, start_ms: int, end_ms: int) -> dict[str, object]:
    return {
        "audioOffset": start_ms * 10_000,
        "duration": (end_ms - start_ms) * 10_000,
        "text": text,
    }


def _azure_viseme(viseme: int, at_ms: int) -> dict[str, object]:
    return {"audioOffset": at_ms * 10_000, "visemeId": viseme}


def test_an_azure_word_waits_for_its_visemes_in_the_next_chunk() -> None:
    stream = WordStream()
    first = stream.take(parse_timings([_azure_word("map", 100, 400), _azure_viseme(21, 100)]))
    assert first == []  # "map" is over only when an event at or after 0.4 s comes
    second = stream.take(parse_timings([_azure_viseme(2, 200), _azure_viseme(21, 300)]))
    assert second == []
    third = stream.take(parse_timings([_azure_viseme(0, 400), _azure_word("on", 500, 700)]))
    [released] = [word for timings in third for word in timings.words]
    assert released.text == "map"
    assert (released.start, released.end) == pytest.approx((0.1, 0.4))
    assert [v.viseme for v in released.visemes] == ["21", "2", "21"]
    assert [v.start for v in released.visemes] == pytest.approx([0.1, 0.2, 0.3])
    assert [w.text for t in stream.finish() for w in t.words] == ["on"]


def test_a_polly_word_is_closed_by_a_later_chunks_sil_mark() -> None:
    stream = WordStream()
    word = '{"time":100,"type":"word","start":0,"end":3,"value":"map"}'
    assert stream.take(parse_timings(word)) == []
    visemes = '{"time":100,"type":"viseme","value":"p"}\n{"time":200,"type":"viseme","value":"a"}'
    assert stream.take(parse_timings(visemes)) == []
    out = stream.take(parse_timings('{"time":350,"type":"viseme","value":"sil"}'))
    [released] = [w for t in out for w in t.words]
    assert released.text == "map" and released.end == pytest.approx(0.35)
    assert [v.viseme for v in released.visemes] == ["p", "a"]


def test_a_viseme_for_a_released_word_is_non_monotonic_and_names_it() -> None:
    stream = WordStream()
    stream.take(parse_timings([_azure_word("map", 100, 400), _azure_viseme(21, 100)]))
    stream.take(parse_timings([_azure_word("on", 500, 700), _azure_viseme(4, 500)]))
    with pytest.raises(LipstreamError) as raised:
        stream.take(parse_timings([_azure_viseme(2, 200)]))
    assert raised.value.code == "non_monotonic_times" and raised.value.where == "events[0]"
