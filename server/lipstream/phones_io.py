"""Phone files in and frame files out, for ``lipstream synth`` and batch tools.

Phones: a Praat TextGrid (the phone tier of MFA, WebMAUS and other aligners,
or a named one; see ``corpus.tiers``), an HTK/MOCHA ``.lab``, or JSON
``[{"phoneme": ..., "start": s, "end": s}, ...]``. Frames: any format of
``lipstream.exports`` (corpus CSV, JSON, Live Link Face CSV, Rhubarb, Moho),
named or chosen by extension.
"""

from __future__ import annotations

import json
from pathlib import Path

from .corpus import read_lab_phones, read_textgrid_phones
from .engines.base import SynthesisResult
from .errors import InvalidRequestError, LipstreamError
from .exports.writer import ExportSettings, write_export
from .timeline import PhonemeSpan, coerce_spans


def _read_json_phones(path: Path) -> list[PhonemeSpan]:
    try:
        items = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InvalidRequestError(f"cannot read JSON phones: {exc}", where=str(path)) from None
    if not isinstance(items, list):
        raise InvalidRequestError("JSON phones must be a list of spans", where=str(path))
    try:
        return coerce_spans(items, source="auto")
    except LipstreamError as error:
        raise type(error)(error.message, where=f"{path}: {error.where}", code=error.code) from None


def read_phones(path: Path, tier: str | None = None) -> list[PhonemeSpan]:
    """Spans from a .TextGrid (its phone tier, or the one named ``tier``), .lab or .json file,
    chosen by extension."""
    suffix = path.suffix.lower()
    if suffix == ".textgrid":
        return read_textgrid_phones(path, tier)
    if suffix == ".lab":
        return read_lab_phones(path)
    if suffix == ".json":
        return _read_json_phones(path)
    raise InvalidRequestError(
        f"unsupported phones file type {path.suffix!r} (use .TextGrid, .lab or .json)",
        where=str(path),
    )


def write_frames(
    path: Path,
    result: SynthesisResult,
    format_name: str | None = None,
    settings: ExportSettings | None = None,
) -> str:
    """Write frames in ``format_name`` (one of ``exports.FORMATS``), else by extension
    (``.csv``, ``.json``, ``.tsv``, ``.xml``, ``.dat``); returns the format written."""
    return write_export(path, result, format_name, settings)
