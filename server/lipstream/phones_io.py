"""Phone files in and frame files out, for ``lipstream synth`` and batch tools.

Phones: a Praat TextGrid (tier ``phones``), an HTK/MOCHA ``.lab``, or JSON
``[{"phoneme": ..., "start": s, "end": s}, ...]``. Frames: CSV in the corpus
format (``time`` plus one column per channel) or JSON
``{"fps", "channels", "frames": [[...], ...]}``, chosen by extension.
"""

from __future__ import annotations

import json
from pathlib import Path

from .corpus import read_lab_phones, read_textgrid_phones, write_frames_csv
from .engines.base import SynthesisResult
from .errors import InvalidRequestError, LipstreamError
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


def read_phones(path: Path) -> list[PhonemeSpan]:
    """Spans from a .TextGrid, .lab or .json file, chosen by extension."""
    suffix = path.suffix.lower()
    if suffix == ".textgrid":
        return read_textgrid_phones(path)
    if suffix == ".lab":
        return read_lab_phones(path)
    if suffix == ".json":
        return _read_json_phones(path)
    raise InvalidRequestError(
        f"unsupported phones file type {path.suffix!r} (use .TextGrid, .lab or .json)",
        where=str(path),
    )


def write_frames(path: Path, result: SynthesisResult) -> None:
    """Write frames as CSV (corpus format) or JSON, chosen by extension."""
    suffix = path.suffix.lower()
    if suffix == ".csv":
        write_frames_csv(path, result.frames, result.channels, result.fps)
    elif suffix == ".json":
        payload = {
            "fps": result.fps,
            "channels": list(result.channels),
            "frames": result.frames.round(6).tolist(),
            "stats": result.stats,
        }
        path.write_text(json.dumps(payload) + "\n", encoding="utf-8")
    else:
        raise InvalidRequestError(
            f"unsupported output type {path.suffix!r} (use .csv or .json)", where=str(path)
        )
