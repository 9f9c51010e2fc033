"""Per-utterance metadata, ``<stem>.json``: ``{"emotion": ..., "speaker": ..., "text": ...,
"alignment_confidence": ...}``.

Sketch: parse the JSON (syntax errors name file:line:column) and require an
object whose known keys have the right type; a wrong value is refused. Other
keys (corpora carry all sorts: durations, ids, notes) are ignored with a
``CorpusWarning`` naming the file and key. ``read_json_object`` is shared
with ``config`` for ``corpus.json``, which stays strict about its keys.
"""

from __future__ import annotations

import json
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import CorpusError
from ..timeline import EMOTIONS
from .validation import at_line

METADATA_KEYS = ("emotion", "speaker", "text", "alignment_confidence")


class CorpusWarning(UserWarning):
    """Something in a corpus was ignored; the message names the file and what."""


@dataclass(frozen=True)
class UtteranceMetadata:
    emotion: str = "neutral"
    speaker: str | None = None
    text: str | None = None
    alignment_confidence: float | None = None


def read_json_object(
    path: Path, allowed_keys: tuple[str, ...], *, strict: bool = True
) -> dict[str, Any]:
    """A JSON object holding only ``allowed_keys``: any other key raises when ``strict``,
    else is dropped with a ``CorpusWarning``."""
    try:
        text = path.read_text(encoding="utf-8-sig")
    except OSError as exc:
        raise CorpusError(f"cannot read file: {exc.strerror}", where=str(path)) from None
    except UnicodeDecodeError:
        raise CorpusError("file is not UTF-8 text", where=path.name) from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise CorpusError(
            f"invalid JSON: {exc.msg} (column {exc.colno})", where=at_line(path.name, exc.lineno)
        ) from None
    if not isinstance(data, dict):
        raise CorpusError(f"must hold a JSON object, found {type(data).__name__}", where=path.name)
    unknown = [key for key in data if key not in allowed_keys]
    if unknown and strict:
        raise CorpusError(
            f"unknown key {unknown[0]!r}; allowed keys: {', '.join(allowed_keys)}",
            where=path.name,
        )
    for key in unknown:
        warnings.warn(
            f"{path.name}: unknown key {key!r} ignored; known keys: {', '.join(allowed_keys)}",
            CorpusWarning,
            stacklevel=2,
        )
    return {key: value for key, value in data.items() if key in allowed_keys}


def read_utterance_metadata(path: str | Path) -> UtteranceMetadata:
    path = Path(path)
    data = read_json_object(path, METADATA_KEYS, strict=False)
    emotion = data.get("emotion", "neutral")
    if not isinstance(emotion, str) or emotion not in EMOTIONS:
        raise CorpusError(
            f"key 'emotion' must be one of {', '.join(EMOTIONS)}, got {emotion!r}",
            where=path.name,
        )
    return UtteranceMetadata(
        emotion,
        _optional_text(path, data, "speaker"),
        _optional_text(path, data, "text"),
        _optional_share(path, data, "alignment_confidence"),
    )


def _optional_share(path: Path, data: dict[str, Any], key: str) -> float | None:
    value = data.get(key)
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float) or not 0.0 <= value <= 1.0:
        raise CorpusError(f"key {key!r} must be a number in [0, 1], got {value!r}", where=path.name)
    return float(value)


def _optional_text(path: Path, data: dict[str, Any], key: str) -> str | None:
    value = data.get(key)
    if value is not None and not isinstance(value, str):
        raise CorpusError(
            f"key {key!r} must be a string, got {type(value).__name__}", where=path.name
        )
    return value


def write_utterance_metadata(path: Path, metadata: UtteranceMetadata) -> None:
    data: dict[str, str | float] = {"emotion": metadata.emotion}
    if metadata.speaker is not None:
        data["speaker"] = metadata.speaker
    if metadata.text is not None:
        data["text"] = metadata.text
    if metadata.alignment_confidence is not None:
        data["alignment_confidence"] = round(metadata.alignment_confidence, 4)
    path.write_text(json.dumps(data, indent=2, ensure_ascii=False) + "\n", encoding="utf-8")
