"""Phoneme timestamps in IPA: Cartesia's ``{"phonemes": [...], "start": [...], "end":
[...]}`` (seconds; also inside its ``phoneme_timestamps`` message), Hume's timestamp
messages ``{"type": "timestamp", "timestamp": {"type": "phoneme", "text": "h", "time":
{"begin": ms, "end": ms}}}`` (word timestamps among them are skipped), and a plain list
of ``{"phoneme", "start", "end"}`` in seconds.

Sketch: each label goes through the IPA reader of ``phonemes.normalize_phoneme`` (stress
and length marks dropped, diacritics tried with and without); a gap between two phonemes
becomes silence when the spans are joined (``words_to_spans``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from lipstream_client.errors import MISMATCHED_WORDS

from ...errors import LipstreamError
from ...phonemes import normalize_phoneme
from ...timeline import PhonemeSpan
from ..timing_checks import check_order, check_span, seconds
from ..timings import SpeechTimings
from .fields import array, mapping, member, text

MS = 1e-3


def parse_ipa(data: Any) -> SpeechTimings:
    if isinstance(data, Mapping) and "phoneme_timestamps" in data:
        return parse_ipa(mapping(data["phoneme_timestamps"], "phoneme_timestamps"))
    if isinstance(data, Mapping):
        items = _parallel(data)
    else:
        items = []
        for index, item in enumerate(array(data, "phonemes")):
            parsed = _item(mapping(item, f"phonemes[{index}]"), f"phonemes[{index}]")
            if parsed is not None:
                items.append(parsed)
    check_order([(start, end, where) for _, start, end, where in items], "phonemes")
    spans = [
        PhonemeSpan(normalize_phoneme(label, "ipa", where), start, end)
        for label, start, end, where in items
        if end > start
    ]
    return SpeechTimings("ipa", phonemes=tuple(spans))


def _parallel(data: Mapping[str, Any]) -> list[tuple[str, float, float, str]]:
    labels = array(member(data, ("phonemes",), "input")[0], "phonemes")
    starts = array(member(data, ("start",), "input")[0], "start")
    ends = array(member(data, ("end",), "input")[0], "end")
    if not len(labels) == len(starts) == len(ends):
        raise LipstreamError(
            f"{len(labels)} phonemes but {len(starts)} starts and {len(ends)} ends",
            where="phonemes",
            code=MISMATCHED_WORDS,
        )
    items = []
    for index, (label, start, end) in enumerate(zip(labels, starts, ends)):
        where = f"phonemes[{index}]"
        start_s, end_s = seconds(start, f"start[{index}]"), seconds(end, f"end[{index}]")
        check_span(start_s, end_s, where)
        items.append((text(label, where), start_s, end_s, where))
    return items


def _item(item: Mapping[str, Any], where: str) -> tuple[str, float, float, str] | None:
    if "timestamp" in item:  # Hume
        stamp = mapping(item["timestamp"], f"{where}.timestamp")
        where = f"{where}.timestamp"
        if stamp.get("type") != "phoneme":
            return None
        label = text(member(stamp, ("text",), where)[0], f"{where}.text")
        time = mapping(member(stamp, ("time",), where)[0], f"{where}.time")
        start = seconds(member(time, ("begin",), f"{where}.time")[0], f"{where}.time.begin", MS)
        end = seconds(member(time, ("end",), f"{where}.time")[0], f"{where}.time.end", MS)
    else:
        label = text(member(item, ("phoneme",), where)[0], f"{where}.phoneme")
        start = seconds(member(item, ("start",), where)[0], f"{where}.start")
        end = seconds(member(item, ("end",), where)[0], f"{where}.end")
    check_span(start, end, where)
    return label, start, end, where


def looks_like_ipa(data: Any) -> bool:
    if isinstance(data, Mapping):
        return "phoneme_timestamps" in data or "phonemes" in data
    if isinstance(data, list) and data and isinstance(data[0], Mapping):
        first = data[0]
        return "phoneme" in first or (
            first.get("type") == "timestamp" and isinstance(first.get("timestamp"), Mapping)
        )
    return False
