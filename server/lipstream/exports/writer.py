"""Writing a synthesis result in one export format.

Sketch: the corpus CSV and JSON are the frames as they are; ``livelink``
renames onto Live Link Face's columns; the Rhubarb and Moho formats first
turn Preston Blair shape weights into mouth cues (``cues``).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from ..corpus.frames_csv import frames_csv_text
from ..engines.base import SynthesisResult
from ..errors import InvalidRequestError
from .cues import mouth_cues
from .formats import MOHO_FPS, format_for
from .livelink import livelink_csv
from .moho import moho_dat
from .rhubarb import rhubarb_json, rhubarb_tsv, rhubarb_xml


@dataclass(frozen=True)
class ExportSettings:
    """``sound_file``: the recording Rhubarb's metadata names; ``moho_fps``: Moho's frame rate."""

    sound_file: str = ""
    moho_fps: float = MOHO_FPS


def export_text(
    result: SynthesisResult, format_name: str, settings: ExportSettings | None = None
) -> str:
    """The text of ``result`` in ``format_name`` (one of ``FORMATS``)."""
    settings = settings or ExportSettings()
    frames, channels, fps = result.frames, result.channels, result.fps
    if format_name == "csv":
        return frames_csv_text(frames, channels, fps)
    if format_name == "json":
        payload = {
            "fps": fps,
            "channels": list(channels),
            "frames": frames.round(6).tolist(),
            "stats": result.stats,
        }
        return json.dumps(payload) + "\n"
    if format_name == "livelink":
        return livelink_csv(frames, channels, fps)
    cues = mouth_cues(frames, channels, fps)
    if format_name == "rhubarb-tsv":
        return rhubarb_tsv(cues)
    if format_name == "rhubarb-xml":
        return rhubarb_xml(cues, settings.sound_file)
    if format_name == "rhubarb-json":
        return rhubarb_json(cues, settings.sound_file)
    if format_name == "moho":
        return moho_dat(cues, settings.moho_fps)
    raise InvalidRequestError(f"unknown output format {format_name!r}", where="format")


def write_export(
    path: Path,
    result: SynthesisResult,
    format_name: str | None = None,
    settings: ExportSettings | None = None,
) -> str:
    """Write ``result`` to ``path`` in ``format_name`` (else by extension); the format used."""
    chosen = format_for(path, format_name)
    path.write_text(export_text(result, chosen, settings), encoding="utf-8", newline="")
    return chosen
