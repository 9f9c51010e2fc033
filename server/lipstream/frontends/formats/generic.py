"""The generic word list: ``[{"word": "Hello", "start": 0.12, "end": 0.46}, ...]`` in
seconds (``text`` for ``word`` also reads), wrapped or not in ``{"words": [...]}``; and
the same as parallel arrays, ``{"words": [...], "start": [...], "end": [...]}``, which is
Cartesia's ``word_timestamps`` (read also inside its timestamps message)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from lipstream_client.errors import MISMATCHED_WORDS

from ...errors import LipstreamError
from ..timing_checks import check_order, check_span, seconds
from ..timings import SpeechTimings, TimedWord
from .fields import array, mapping, member, text

WORD_KEYS = ("word", "text")


def parse_words(data: Any) -> SpeechTimings:
    if isinstance(data, Mapping) and "word_timestamps" in data:
        return parse_words(mapping(data["word_timestamps"], "word_timestamps"))
    if isinstance(data, Mapping) and isinstance(data.get("start"), list):
        return _parallel(data)
    if isinstance(data, Mapping):
        data, where = member(data, ("words",), "input")
    else:
        where = "words"
    words = [_word(item, f"{where}[{index}]") for index, item in enumerate(array(data, where))]
    check_order([(word.start, word.end, word.where) for word in words], "words")
    return SpeechTimings("words", words=tuple(words))


def _word(item: Any, where: str) -> TimedWord:
    item = mapping(item, where)
    word, word_where = member(item, WORD_KEYS, where)
    start = seconds(member(item, ("start",), where)[0], f"{where}.start")
    end = seconds(member(item, ("end",), where)[0], f"{where}.end")
    check_span(start, end, where)
    return TimedWord(text(word, word_where), start, end, where)


def _parallel(data: Mapping[str, Any]) -> SpeechTimings:
    texts: Sequence[Any] = array(member(data, ("words",), "input")[0], "words")
    starts = array(data["start"], "start")
    ends = array(member(data, ("end",), "input")[0], "end")
    if not len(texts) == len(starts) == len(ends):
        raise LipstreamError(
            f"{len(texts)} words but {len(starts)} starts and {len(ends)} ends",
            where="words",
            code=MISMATCHED_WORDS,
        )
    words = []
    for index, (word, start, end) in enumerate(zip(texts, starts, ends)):
        where = f"words[{index}]"
        start_s, end_s = seconds(start, f"start[{index}]"), seconds(end, f"end[{index}]")
        check_span(start_s, end_s, where)
        words.append(TimedWord(text(word, where), start_s, end_s, where))
    check_order([(word.start, word.end, word.where) for word in words], "words")
    return SpeechTimings("words", words=tuple(words))


def looks_like_words(data: Any) -> bool:
    if isinstance(data, Mapping):
        return "word_timestamps" in data or (
            isinstance(data.get("words"), list) and "phonemes" not in data
        )
    if isinstance(data, list) and data and isinstance(data[0], Mapping):
        keys = set(data[0])
        return bool(keys & set(WORD_KEYS)) and {"start", "end"} <= keys
    return False
