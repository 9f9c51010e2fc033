"""The optional ``corpus.json``: name, frame rate, channels, held-out stems, phone tier.

Sketch: ``{"name": str, "fps": number, "channels": [str], "heldout": [str],
"tier": str}``,
every key optional. Each value is type-checked and any other key is refused,
with the file and key in the message. Whether the channels and stems exist is
checked later, against the frames (``validation``) and the stems found.
"""

from __future__ import annotations

import json
import math
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import CorpusError
from .metadata import read_json_object

CONFIG_FILE = "corpus.json"
CONFIG_KEYS = ("name", "fps", "channels", "heldout", "tier")


@dataclass(frozen=True)
class CorpusConfig:
    """``None`` means the key was absent."""

    name: str | None = None
    fps: float | None = None
    channels: tuple[str, ...] | None = None
    heldout: tuple[str, ...] = ()
    tier: str | None = None


def read_corpus_config(path: str | Path) -> CorpusConfig:
    path = Path(path)
    data = read_json_object(path, CONFIG_KEYS)
    name, tier = _text(path, data, "name"), _text(path, data, "tier")
    channels = _names(path, data, "channels")
    if channels == ():
        raise CorpusError("key 'channels' must list at least one channel", where=path.name)
    return CorpusConfig(
        name=name,
        fps=_fps(path, data) if "fps" in data else None,
        channels=channels,
        heldout=_names(path, data, "heldout") or (),
        tier=tier,
    )


def _text(path: Path, data: dict[str, Any], key: str) -> str | None:
    value = data.get(key)
    if key in data and (not isinstance(value, str) or not value):
        raise CorpusError(f"key {key!r} must be a non-empty string, got {value!r}", where=path.name)
    return value if isinstance(value, str) else None


def _fps(path: Path, data: dict[str, Any]) -> float:
    value = data["fps"]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise CorpusError(f"key 'fps' must be a number, got {value!r}", where=path.name)
    if not (math.isfinite(value) and value > 0):
        raise CorpusError(f"key 'fps' must be positive and finite, got {value!r}", where=path.name)
    return float(value)


def _names(path: Path, data: dict[str, Any], key: str) -> tuple[str, ...] | None:
    if key not in data:
        return None
    value = data[key]
    if not isinstance(value, list) or not all(isinstance(item, str) and item for item in value):
        raise CorpusError(f"key {key!r} must be a list of non-empty strings", where=path.name)
    duplicates = sorted(item for item, count in Counter(value).items() if count > 1)
    if duplicates:
        raise CorpusError(
            f"key {key!r} lists {', '.join(duplicates)} more than once", where=path.name
        )
    return tuple(value)


def write_corpus_config(path: Path, config: CorpusConfig) -> None:
    data: dict[str, Any] = {}
    if config.name is not None:
        data["name"] = config.name
    if config.fps is not None:
        data["fps"] = config.fps
    if config.channels is not None:
        data["channels"] = list(config.channels)
    if config.heldout:
        data["heldout"] = list(config.heldout)
    if config.tier is not None:
        data["tier"] = config.tier
    path.write_text(json.dumps(data, indent=2, ensure_ascii=False) + "\n", encoding="utf-8")
