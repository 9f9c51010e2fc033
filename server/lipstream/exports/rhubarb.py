"""Rhubarb Lip Sync's output formats (``-f tsv``, ``-f xml``, ``-f json``), written as it does.

Sketch: times are seconds with two decimals (Rhubarb counts centiseconds).
TSV: one ``start<TAB>shape`` line per cue, then the end time with the closed
mouth ``X``. XML: ``rhubarbResult`` holding ``metadata`` (``soundFile``,
``duration``) and ``mouthCues``, each ``<mouthCue start= end=>shape``,
indented by two spaces. JSON: the same, hand-formatted as Rhubarb formats
it. With no cues, XML and JSON hold one zero-length ``X`` cue, as Rhubarb's do.
"""

from __future__ import annotations

import json
from xml.sax.saxutils import escape, quoteattr

from .cues import REST_SHAPE, MouthCue, MouthCues


def rhubarb_tsv(cues: MouthCues) -> str:
    lines = [f"{_seconds(cue.start)}\t{cue.value}" for cue in cues.cues]
    lines.append(f"{_seconds(cues.end)}\t{REST_SHAPE}")
    return "\n".join(lines) + "\n"


def rhubarb_xml(cues: MouthCues, sound_file: str = "") -> str:
    lines = [
        '<?xml version="1.0" encoding="utf-8"?>',
        "<rhubarbResult>",
        "  <metadata>",
        f"    <soundFile>{escape(sound_file)}</soundFile>",
        f"    <duration>{_seconds(cues.end)}</duration>",
        "  </metadata>",
        "  <mouthCues>",
    ]
    lines += [
        f"    <mouthCue start={quoteattr(_seconds(cue.start))} "
        f"end={quoteattr(_seconds(cue.end))}>{cue.value}</mouthCue>"
        for cue in _at_least_one(cues)
    ]
    lines += ["  </mouthCues>", "</rhubarbResult>"]
    return "\n".join(lines) + "\n"


def rhubarb_json(cues: MouthCues, sound_file: str = "") -> str:
    entries = [
        f'    {{ "start": {_seconds(cue.start)}, "end": {_seconds(cue.end)}, '
        f'"value": "{cue.value}" }}'
        for cue in _at_least_one(cues)
    ]
    lines = [
        "{",
        '  "metadata": {',
        f'    "soundFile": {json.dumps(sound_file, ensure_ascii=False)},',
        f'    "duration": {_seconds(cues.end)}',
        "  },",
        '  "mouthCues": [',
        ",\n".join(entries),
        "  ]",
        "}",
    ]
    return "\n".join(lines) + "\n"


def _at_least_one(cues: MouthCues) -> tuple[MouthCue, ...]:
    return cues.cues or (MouthCue(0, 0, REST_SHAPE),)


def _seconds(centiseconds: int) -> str:
    return f"{centiseconds // 100}.{centiseconds % 100:02d}"
