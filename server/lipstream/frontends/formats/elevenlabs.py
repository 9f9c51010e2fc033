"""ElevenLabs' character alignment: ``{"characters": [...],
"character_start_times_seconds": [...], "character_end_times_seconds": [...]}``, as the
``alignment`` and ``normalized_alignment`` of its with-timestamps responses.

Sketch: a response (or a list of streamed chunks, each with its own alignment, times on
the utterance clock) is read as one run of characters; ``normalized_alignment`` is
preferred, as its text is what the voice said (numbers spelled out). White space
separates words: a word runs from its first character's start to its last one's end and
keeps every character's time. The three arrays must be of one length and every entry one
character (``mismatched_words``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from lipstream_client.errors import MISMATCHED_WORDS

from ...errors import LipstreamError
from ..timing_checks import check_order, check_span, seconds
from ..timings import SpeechTimings, TimedCharacter, TimedWord
from .fields import array, mapping, member, text

ALIGNMENT_KEYS = ("normalized_alignment", "normalizedAlignment", "alignment")
CHARACTERS = "characters"
STARTS = ("character_start_times_seconds", "characterStartTimesSeconds")
ENDS = ("character_end_times_seconds", "characterEndTimesSeconds")


def parse_elevenlabs(data: Any) -> SpeechTimings:
    chunks = data if isinstance(data, list) else [data]
    characters: list[tuple[TimedCharacter, str]] = []
    for index, chunk in enumerate(chunks):
        where = f"[{index}]" if isinstance(data, list) else ""
        characters += _characters(mapping(chunk, where or "input"), where)
    check_order([(c.start, c.end, where) for c, where in characters], "characters")
    return SpeechTimings(
        "elevenlabs",
        words=tuple(_words(characters)),
        continues_word=bool(characters) and not characters[0][0].char.isspace(),
        last_word_open=bool(characters) and not characters[-1][0].char.isspace(),
    )


def _alignment(chunk: Mapping[str, Any], where: str) -> tuple[Mapping[str, Any], str]:
    for key in ALIGNMENT_KEYS:
        if isinstance(chunk.get(key), Mapping):
            return chunk[key], f"{where}.{key}".lstrip(".")
    return chunk, where or "alignment"


def _characters(chunk: Mapping[str, Any], where: str) -> list[tuple[TimedCharacter, str]]:
    alignment, where = _alignment(chunk, where)
    chars = array(member(alignment, (CHARACTERS,), where)[0], f"{where}.{CHARACTERS}")
    starts = array(member(alignment, STARTS, where)[0], f"{where}.{STARTS[0]}")
    ends = array(member(alignment, ENDS, where)[0], f"{where}.{ENDS[0]}")
    if not len(chars) == len(starts) == len(ends):
        raise LipstreamError(
            f"{len(chars)} characters but {len(starts)} start times and {len(ends)} end times",
            where=where,
            code=MISMATCHED_WORDS,
        )
    result = []
    for index, (char, start, end) in enumerate(zip(chars, starts, ends)):
        place = f"{where}.{CHARACTERS}[{index}]"
        char = text(char, place)
        if len(char) != 1:
            raise LipstreamError(
                f"an entry of characters must be one character, got {char!r}",
                where=place,
                code=MISMATCHED_WORDS,
            )
        start_s = seconds(start, f"{where}.{STARTS[0]}[{index}]")
        end_s = seconds(end, f"{where}.{ENDS[0]}[{index}]")
        check_span(start_s, end_s, place)
        result.append((TimedCharacter(char, start_s, end_s), place))
    return result


def _words(characters: list[tuple[TimedCharacter, str]]) -> list[TimedWord]:
    words: list[TimedWord] = []
    run: list[tuple[TimedCharacter, str]] = []
    for item in characters + [(TimedCharacter(" ", 0.0, 0.0), "")]:
        if not item[0].char.isspace():
            run.append(item)
            continue
        if run:
            chars = tuple(char for char, _ in run)
            word = "".join(char.char for char in chars)
            words.append(TimedWord(word, chars[0].start, chars[-1].end, run[0][1], chars))
            run = []
    return words


def looks_like_elevenlabs(data: Any) -> bool:
    first = data[0] if isinstance(data, list) and data else data
    if not isinstance(first, Mapping):
        return False
    return CHARACTERS in first or any(isinstance(first.get(key), Mapping) for key in ALIGNMENT_KEYS)
