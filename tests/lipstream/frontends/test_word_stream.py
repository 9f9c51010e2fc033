"""Timings in chunks: a word cut at a chunk's edge is held and joined, a Polly word's end
comes from the next word, and whatever is held is released at the end."""

from __future__ import annotations

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
