"""Phoneme spans: the timeline every step of the pipeline consumes.

A span is ``(phoneme, start, end)`` in seconds on the utterance clock, with an
optional ``emotion`` that overrides the request's for that span. Callers may
pass tuples ``(phoneme, start, end[, emotion])`` or mappings with those keys;
``coerce_spans`` turns them into validated ``PhonemeSpan`` objects with
canonical ARPAbet labels. Labels are normalized once, at the edge input comes in by:
``Synthesizer.feed`` normalizes whatever it is given (``coerce_spans``), except
``NormalizedSpans``, which an edge that normalized them already (the server's request)
hands on and which are only checked to follow the input so far (``follow_checked``).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, TypeGuard, Union

from .errors import InvalidRequestError, LipstreamError
from .phonemes import kept_labels, normalize_phoneme

SpanLike = Union["PhonemeSpan", Sequence[Any], Mapping[str, Any]]
EMOTIONS = ("neutral", "happy", "angry", "sad")
EMOTION_INDEX = {emotion: index for index, emotion in enumerate(EMOTIONS)}
"""Each emotion's position in ``EMOTIONS``: the index the engines store and look up."""


@dataclass(frozen=True, slots=True)
class PhonemeSpan:
    """One phoneme occurrence: canonical label, [start, end) in seconds, and the emotion it
    is spoken with (None: the request's)."""

    phoneme: str
    start: float
    end: float
    emotion: str | None = None

    @property
    def duration(self) -> float:
        return self.end - self.start

    @property
    def centre(self) -> float:
        return 0.5 * (self.start + self.end)


def _fields(span: SpanLike, where: str) -> tuple[Any, Any, Any, Any]:
    if type(span) is tuple and len(span) in (3, 4):  # the common case, before the ABC checks
        return span[0], span[1], span[2], span[3] if len(span) == 4 else None
    if isinstance(span, PhonemeSpan):
        return span.phoneme, span.start, span.end, span.emotion
    if isinstance(span, Mapping):
        try:
            return span["phoneme"], span["start"], span["end"], span.get("emotion")
        except KeyError as missing:
            raise InvalidRequestError(f"span lacks key {missing}", where=where) from None
    if isinstance(span, Sequence) and not isinstance(span, str) and len(span) in (3, 4):
        return span[0], span[1], span[2], span[3] if len(span) == 4 else None
    raise InvalidRequestError(
        "span must be (phoneme, start, end[, emotion]) or a mapping with those keys",
        where=where,
    )


def check_emotion(emotion: Any, where: str) -> str | None:
    """``emotion`` if it is None or one of ``EMOTIONS``; else InvalidRequestError
    (code ``unknown_emotion``) at ``where``."""
    if emotion is not None and emotion not in EMOTIONS:
        raise InvalidRequestError(
            f"unknown emotion {emotion!r}; known: {', '.join(EMOTIONS)}",
            where=where,
            code="unknown_emotion",
        )
    return None if emotion is None else str(emotion)


def coerce_span(span: SpanLike, where: str = "span", source: str = "request") -> PhonemeSpan:
    """Validate one span and normalize its label (see ``phonemes.normalize_phoneme``)."""
    label, start, end, emotion = _fields(span, where)
    if not isinstance(label, str):
        raise InvalidRequestError("phoneme must be a string", where=where)
    try:
        start_s, end_s = float(start), float(end)
    except (TypeError, ValueError):
        raise InvalidRequestError("start and end must be numbers", where=where) from None
    if not (math.isfinite(start_s) and math.isfinite(end_s)):
        raise InvalidRequestError("start and end must be finite", where=where)
    if start_s < 0 or end_s <= start_s:
        raise InvalidRequestError(
            f"span must satisfy 0 <= start < end, got start={start_s} end={end_s}", where=where
        )
    return PhonemeSpan(
        normalize_phoneme(label, source=source, where=where),
        start_s,
        end_s,
        check_emotion(emotion, f"{where}.emotion"),
    )


class NormalizedSpans(tuple[PhonemeSpan, ...]):
    """Spans an edge has checked and whose labels it has normalized to canonical ARPAbet
    (as ``coerce_span`` would): ``Synthesizer.feed`` takes them as they are."""

    __slots__ = ()


def _valid_as_is(span: SpanLike, source: str) -> TypeGuard[PhonemeSpan]:
    """Whether ``span`` is a ``PhonemeSpan`` that ``coerce_span`` would return unchanged: the
    check costs a fraction of building a new span (callers of the Python API often pass
    ``PhonemeSpan`` objects)."""
    if type(span) is not PhonemeSpan or type(span.start) is not float:
        return False
    if type(span.end) is not float or not (0.0 <= span.start < span.end < math.inf):
        return False
    if span.emotion is not None and span.emotion not in EMOTIONS:
        return False
    try:
        return type(span.phoneme) is str and span.phoneme in kept_labels(source)
    except LipstreamError:
        return False


def coerce_spans(
    spans: Iterable[SpanLike],
    *,
    after: float = 0.0,
    source: str = "request",
    first_index: int = 0,
) -> list[PhonemeSpan]:
    """Validate a run of spans that must follow each other without overlap.

    ``after`` is the end of the last span already accepted; ``first_index``
    numbers the spans in error locations.
    """
    result: list[PhonemeSpan] = []
    previous_end = after
    for offset, raw in enumerate(spans):
        if _valid_as_is(raw, source):
            span = raw
        else:
            span = coerce_span(raw, f"spans[{first_index + offset}]", source)
        _check_follows(span, previous_end, first_index + offset)
        result.append(span)
        previous_end = span.end
    return result


def _check_follows(span: PhonemeSpan, previous_end: float, index: int) -> None:
    if span.start < previous_end - 1e-9:
        raise InvalidRequestError(
            f"span starts at {span.start} before the previous span ends at {previous_end}",
            where=f"spans[{index}]",
            code="non_monotonic_times",
        )


def follow_checked(spans: NormalizedSpans, after: float, first_index: int) -> NormalizedSpans:
    """``spans``, once checked to follow one another from ``after`` (``first_index``: the
    index error locations give the first)."""
    previous_end = after
    for offset, span in enumerate(spans):
        _check_follows(span, previous_end, first_index + offset)
        previous_end = span.end
    return spans
