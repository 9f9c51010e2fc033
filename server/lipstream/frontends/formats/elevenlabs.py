"""ElevenLabs' character alignment: ``{"characters": [...],
"character_start_times_seconds": [...], "character_end_times_seconds": [...]}``, as the
``alignment`` and ``normalized_alignment`` of its with-timestamps responses; and its
WebSocket API's ``{"chars": [...], "charStartTimesMs": [...], "charDurationsMs": [...]}``
(``alignment``, ``normalizedAlignment``), whose times count from the start of the audio
chunk that carries them (a ``words`` message's ``offset`` puts them on the utterance
clock).

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
WEBSOCKET_CHARACTERS = "chars"
WEBSOCKET_STARTS_MS = ("charStartTimesMs", "char_start_times_ms")
WEBSOCKET_DURATIONS_MS = ("charDurationsMs", "char_durations_ms")
MS = 1e-3


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
    websocket = WEBSOCKET_CHARACTERS in alignment
    key = WEBSOCKET_CHARACTERS if websocket else CHARACTERS
    chars = array(member(alignment, (key,), where)[0], f"{where}.{key}")
    first_keys, second_keys = (
        (WEBSOCKET_STARTS_MS, WEBSOCKET_DURATIONS_MS) if websocket else (STARTS, ENDS)
    )
    firsts = array(member(alignment, first_keys, where)[0], f"{where}.{first_keys[0]}")
    seconds_ = array(member(alignment, second_keys, where)[0], f"{where}.{second_keys[0]}")
    if not len(chars) == len(firsts) == len(seconds_):
        raise LipstreamError(
            f"{len(chars)} characters but {len(firsts)} {first_keys[0]} and "
            f"{len(seconds_)} {second_keys[0]}",
            where=where,
            code=MISMATCHED_WORDS,
        )
    unit = MS if websocket else 1.0
    result = []
    for index, (char, first, second) in enumerate(zip(chars, firsts, seconds_)):
        place = f"{where}.{key}[{index}]"
        char = text(char, place)
        if len(char) != 1:
            raise LipstreamError(
                f"an entry of {key} must be one character, got {char!r}",
                where=place,
                code=MISMATCHED_WORDS,
            )
        start_s = seconds(first, f"{where}.{first_keys[0]}[{index}]", unit)
        second_s = seconds(second, f"{where}.{second_keys[0]}[{index}]", unit)
        end_s = start_s + second_s if websocket else second_s
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
    return (
        CHARACTERS in first
        or WEBSOCKET_CHARACTERS in first
        or any(isinstance(first.get(key), Mapping) for key in ALIGNMENT_KEYS)
    )
