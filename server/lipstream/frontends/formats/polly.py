"""Amazon Polly speech marks: JSON lines of ``{"time": ms, "type": "word"|"viseme"|
"sentence"|"ssml", "start": byte, "end": byte, "value": ...}``.

Sketch: a word mark starts a word at ``time``; Polly gives no end, so a word ends where
the next word or a ``sil`` viseme starts, whichever is first; a last word with no
``sil`` after it is left open (the duration model closes it). Sentence and
SSML marks are skipped. Beside word marks, the viseme marks said within a word anchor its
phonemes' onsets (``viseme_anchors``); alone they become spans (``viseme_spans``). The
``start``/``end`` byte offsets must be ordered (``end`` after
``start``), else ``mismatched_words``. Word marks with viseme marks keep the viseme marks
too (``SpeechTimings.visemes``), so that a stream can give a word the visemes of a later
chunk (``word_stream``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any

from lipstream_client.errors import MISMATCHED_WORDS

from ...errors import LipstreamError
from ..timing_checks import check_order, seconds
from ..timings import SpeechTimings, TimedViseme, TimedWord
from ..viseme_anchors import within_words
from .fields import array, mapping, member, misfit, text

MS = 1e-3
MARK_TYPES = ("word", "viseme", "sentence", "ssml")
VISEMES = ("p", "t", "S", "T", "f", "k", "i", "r", "s", "u", "@", "a", "e", "E", "o", "O", "sil")


def parse_polly(data: Any) -> SpeechTimings:
    if _is_mark(data):  # one line of JSON lines is one JSON document
        data = [data]
    starts: list[tuple[str, float, str]] = []
    visemes: list[TimedViseme] = []
    for index, mark in enumerate(array(data, "marks")):
        where = f"marks[{index}]"
        mark = mapping(mark, where)
        kind = text(member(mark, ("type",), where)[0], f"{where}.type")
        if kind not in MARK_TYPES:
            raise misfit(f"unknown speech mark type {kind!r}", f"{where}.type")
        time = seconds(member(mark, ("time",), where)[0], f"{where}.time", MS)
        value = text(member(mark, ("value",), where)[0], f"{where}.value")
        if kind == "word":
            _check_offsets(mark, where)
            starts.append((value, time, where))
        elif kind == "viseme":
            if value not in VISEMES:
                raise misfit(f"unknown Polly viseme {value!r}", f"{where}.value")
            visemes.append(TimedViseme("polly", value, time, where))
    if not starts:
        check_order([(v.start, None, v.where) for v in visemes], "words or visemes")
        return SpeechTimings("polly", visemes=tuple(visemes))
    check_order([(start, None, where) for _, start, where in starts], "words")
    words = _words(starts, visemes)
    said = within_words([w.start for w in words], [w.end for w in words], visemes)
    words = [replace(word, visemes=group) for word, group in zip(words, said)]
    return SpeechTimings(
        "polly", words=tuple(words), visemes=tuple(visemes), last_word_open=words[-1].end is None
    )


def _check_offsets(mark: Mapping[str, Any], where: str) -> None:
    start, end = mark.get("start"), mark.get("end")
    if start is None or end is None:
        return
    if isinstance(start, bool) or isinstance(end, bool) or not isinstance(start, int):
        raise misfit("start and end are byte offsets (integers)", where)
    if not isinstance(end, int) or not 0 <= start < end:
        raise LipstreamError(
            f"the word's byte offsets must satisfy 0 <= start < end, got {start} and {end}",
            where=where,
            code=MISMATCHED_WORDS,
        )


def _words(starts: list[tuple[str, float, str]], visemes: list[TimedViseme]) -> list[TimedWord]:
    words = []
    for index, (value, start, where) in enumerate(starts):
        following = starts[index + 1][1] if index + 1 < len(starts) else None
        words.append(TimedWord(value, start, word_end(start, following, visemes), where))
    return words


def word_end(start: float, following: float | None, visemes: Sequence[TimedViseme]) -> float | None:
    """Where a word mark at ``start`` ends: at the ``following`` word's start or the first
    ``sil`` viseme after it, whichever comes first; None when neither is known yet."""
    pause = next((v.start for v in visemes if v.viseme == "sil" and v.start > start), None)
    candidates = [time for time in (following, pause) if time is not None]
    return min(candidates) if candidates else None


def _is_mark(data: Any) -> bool:
    return isinstance(data, Mapping) and "time" in data and data.get("type") in MARK_TYPES


def looks_like_polly(data: Any) -> bool:
    return _is_mark(data) or (isinstance(data, list) and bool(data) and _is_mark(data[0]))
