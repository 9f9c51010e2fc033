"""Timing formats in, one ``SpeechTimings`` out; the format named, or detected.

Sketch: ``read_timing_text`` turns a file's text into a JSON value (a JSON document, or
JSON lines as Polly writes them: one object per line). ``detect_format`` names the one
format whose shape the value has: each format's ``looks_like`` tests keys no other
format uses (ElevenLabs' ``characters``, Azure's ``audioOffset``, Polly's ``time`` with a
mark ``type``, a ``phonemes`` or Hume ``timestamp`` list, a ``word`` list); none or more
than one is ``unknown_timing_format``, and the caller names the format.
``parse_timings`` runs the format's parser.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

from lipstream_client.errors import EMPTY_TIMINGS, UNKNOWN_TIMING_FORMAT

from ...errors import LipstreamError
from ..timings import TIMING_FORMATS, SpeechTimings
from .azure import looks_like_azure, parse_azure
from .elevenlabs import looks_like_elevenlabs, parse_elevenlabs
from .generic import looks_like_words, parse_words
from .ipa import looks_like_ipa, parse_ipa
from .polly import looks_like_polly, parse_polly

PARSERS: dict[str, Callable[[Any], SpeechTimings]] = {
    "words": parse_words,
    "elevenlabs": parse_elevenlabs,
    "azure": parse_azure,
    "polly": parse_polly,
    "ipa": parse_ipa,
}
DETECTORS: dict[str, Callable[[Any], bool]] = {
    "words": looks_like_words,
    "elevenlabs": looks_like_elevenlabs,
    "azure": looks_like_azure,
    "polly": looks_like_polly,
    "ipa": looks_like_ipa,
}
assert tuple(PARSERS) == TIMING_FORMATS


def read_timing_text(content: str, where: str = "input") -> Any:
    """The JSON value of ``content``: one JSON document, else JSON lines (a list)."""
    if not content.strip():
        raise LipstreamError("the timings are empty", where=where, code=EMPTY_TIMINGS)
    try:
        return json.loads(content)
    except json.JSONDecodeError as whole:
        lines = [line for line in content.splitlines() if line.strip()]
        items = []
        for number, line in enumerate(lines, 1):
            try:
                items.append(json.loads(line))
            except json.JSONDecodeError as error:
                problem = whole if len(lines) == 1 else error
                raise LipstreamError(
                    f"neither JSON nor JSON lines: {problem.msg}",
                    where=f"{where}:line {number if len(lines) > 1 else whole.lineno}",
                    code=UNKNOWN_TIMING_FORMAT,
                ) from None
        return items


def detect_format(data: Any) -> str:
    """The one format whose shape ``data`` has; ``unknown_timing_format`` otherwise."""
    if data == [] or data == {}:
        raise LipstreamError("the timings are empty", where="input", code=EMPTY_TIMINGS)
    matches = [name for name, looks_like in DETECTORS.items() if looks_like(data)]
    if len(matches) == 1:
        return matches[0]
    if not matches:
        raise LipstreamError(
            f"the timings are in no format lipstream reads ({', '.join(TIMING_FORMATS)})",
            where="input",
            code=UNKNOWN_TIMING_FORMAT,
        )
    raise LipstreamError(
        f"the timings fit several formats ({', '.join(matches)}); name one",
        where="input",
        code=UNKNOWN_TIMING_FORMAT,
    )


def parse_timings(data: Any, format: str = "auto") -> SpeechTimings:
    """``data`` (a JSON value, or text for ``read_timing_text``) read as ``format``
    (one of ``TIMING_FORMATS``, or "auto")."""
    if isinstance(data, str):
        data = read_timing_text(data)
    if format == "auto":
        format = detect_format(data)
    if format not in PARSERS:
        raise LipstreamError(
            f"unknown timing format {format!r}; expected auto or one of "
            f"{', '.join(TIMING_FORMATS)}",
            where="format",
            code=UNKNOWN_TIMING_FORMAT,
        )
    return PARSERS[format](data)


MAX_TIMING_FILE_BYTES = 16 << 20


def read_timing_file(path: Path, format: str = "auto") -> SpeechTimings:
    """The timings in the file ``path`` (UTF-8 JSON or JSON lines, at most 16 MiB)."""
    try:
        with open(path, "rb") as handle:
            raw = handle.read(MAX_TIMING_FILE_BYTES + 1)
    except OSError as error:
        raise LipstreamError(
            f"cannot read the timings: {error.strerror}", where=str(path), code="invalid_request"
        ) from None
    if len(raw) > MAX_TIMING_FILE_BYTES:
        raise LipstreamError(
            f"larger than {MAX_TIMING_FILE_BYTES} bytes", where=str(path), code="invalid_request"
        )
    try:
        content = raw.decode("utf-8-sig")
    except UnicodeDecodeError as error:
        raise LipstreamError(
            f"not UTF-8 text (byte {error.start})", where=str(path), code=UNKNOWN_TIMING_FORMAT
        ) from None
    try:
        return parse_timings(read_timing_text(content, str(path)), format)
    except LipstreamError as error:
        where = error.where or "input"
        if not where.startswith(str(path)):
            error.where = f"{path}: {where}"
        raise LipstreamError(error.message, where=error.where, code=error.code) from None
