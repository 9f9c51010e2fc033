"""Azure Speech events: word boundaries and visemes, offsets in 100-ns ticks.

Sketch: the input is the list of events the Speech SDK raised, each serialized with its
fields (camelCase as the JavaScript SDK names them, ``audioOffset``, ``duration``,
``text``, ``textOffset``, ``wordLength``, ``boundaryType``, ``visemeId``; PascalCase and
snake_case spellings read too), in JSON or one event per line. A word boundary becomes a
word over [audioOffset, audioOffset + duration] (without ``duration``, until the next
word starts; the last such word is left open for the next chunk or the duration model);
punctuation and sentence boundaries are skipped; a ``wordLength`` other than the text's
length is ``mismatched_words``. A viseme event (ID 0-21) starts that viseme; beside word
boundaries, the visemes said within a word anchor its phonemes' onsets
(``viseme_anchors``; the visemes are kept beside the words too, for a stream to give a
word the visemes of a later chunk, ``word_stream``), and alone they become spans
(``viseme_spans``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from typing import Any

from lipstream_client.errors import MISMATCHED_WORDS

from ...errors import LipstreamError
from ..timing_checks import check_order, check_span, seconds
from ..timings import SpeechTimings, TimedViseme, TimedWord
from ..viseme_anchors import within_words
from .fields import array, first_key, mapping, member, misfit, text

TICK_S = 1e-7
OFFSET = ("audioOffset", "AudioOffset", "audio_offset", "privAudioOffset")
DURATION = ("duration", "Duration", "privDuration")
TEXT = ("text", "Text", "privText")
WORD_LENGTH = ("wordLength", "WordLength", "word_length", "privWordLength")
BOUNDARY = ("boundaryType", "BoundaryType", "boundary_type", "privBoundaryType")
VISEME = ("visemeId", "VisemeId", "viseme_id", "privVisemeId")
N_VISEMES = 22


def parse_azure(data: Any) -> SpeechTimings:
    words: list[TimedWord] = []
    visemes: list[TimedViseme] = []
    for index, event in enumerate(array(data, "events")):
        where = f"events[{index}]"
        event = mapping(event, where)
        if first_key(event, VISEME) is not None:
            visemes.append(_viseme(event, where))
        elif first_key(event, TEXT) is not None:
            if _is_word(event, where):
                words.append(_word(event, where))
        else:
            raise misfit("is neither a word boundary (text) nor a viseme (visemeId)", where)
    if words:
        check_order([(word.start, word.end, word.where) for word in words], "words")
        closed = [
            replace(word, end=following.start) if word.end is None else word
            for word, following in zip(words, words[1:])
        ]
        words = closed + words[-1:]
        said = within_words([w.start for w in words], [w.end for w in words], visemes)
        words = [replace(word, visemes=group) for word, group in zip(words, said)]
        return SpeechTimings(
            "azure",
            words=tuple(words),
            visemes=tuple(visemes),
            last_word_open=words[-1].end is None,
        )
    check_order([(v.start, None, v.where) for v in visemes], "words or visemes")
    return SpeechTimings("azure", visemes=tuple(visemes))


def _is_word(event: Mapping[str, Any], where: str) -> bool:
    key = first_key(event, BOUNDARY)
    if key is None:
        return True
    kind = event[key]
    if isinstance(kind, int) and not isinstance(kind, bool):
        return kind == 0
    kind = text(kind, f"{where}.{key}").lower()
    return "punctuation" not in kind and "sentence" not in kind


def _word(event: Mapping[str, Any], where: str) -> TimedWord:
    word, word_where = member(event, TEXT, where)
    word = text(word, word_where)
    offset, offset_where = member(event, OFFSET, where)
    start = seconds(offset, offset_where, TICK_S)
    end = None
    duration_key = first_key(event, DURATION)
    if duration_key is not None:
        end = start + seconds(event[duration_key], f"{where}.{duration_key}", TICK_S)
        check_span(start, end, where)
    length_key = first_key(event, WORD_LENGTH)
    if length_key is not None and event[length_key] != len(word):
        raise LipstreamError(
            f"{length_key} is {event[length_key]!r} but the text {word!r} has {len(word)} "
            "characters",
            where=f"{where}.{length_key}",
            code=MISMATCHED_WORDS,
        )
    return TimedWord(word, start, end, where)


def _viseme(event: Mapping[str, Any], where: str) -> TimedViseme:
    viseme, viseme_where = member(event, VISEME, where)
    if isinstance(viseme, bool) or not isinstance(viseme, int) or not 0 <= viseme < N_VISEMES:
        raise misfit(f"a viseme ID is an integer 0-{N_VISEMES - 1}, got {viseme!r}", viseme_where)
    offset, offset_where = member(event, OFFSET, where)
    return TimedViseme("azure", str(viseme), seconds(offset, offset_where, TICK_S), where)


def looks_like_azure(data: Any) -> bool:
    if not isinstance(data, list) or not data or not isinstance(data[0], Mapping):
        return False
    return first_key(data[0], OFFSET) is not None
