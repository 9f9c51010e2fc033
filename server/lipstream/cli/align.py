"""The ``lipstream align`` command: speech and its transcript to a phones TextGrid.

Sketch: ``lipstream align AUDIO --transcript TEXT|FILE --out FILE.TextGrid`` reads the
audio (a mono WAV, or any file with a sound track PyAV decodes, mixed to mono, when the
capture extra is installed), aligns it (``align``) and writes a TextGrid with a
``phones`` and a ``words`` tier, printing the alignment's confidence.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from ..config import Settings

if TYPE_CHECKING:
    from ..audio import Audio


def add_align_parser(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    align = commands.add_parser(
        "align", help="phones of recorded speech by forced alignment to its transcript"
    )
    align.add_argument("audio", metavar="AUDIO", help="a WAV file, or a video or sound file")
    align.add_argument(
        "--transcript", required=True, help="what is said: the text, or a .txt file holding it"
    )
    align.add_argument("--out", required=True, help="TextGrid to write (tiers phones and words)")
    align.set_defaults(run=run_align)


def run_align(args: argparse.Namespace, settings: Settings) -> None:
    from ..frontends.align import align, write_alignment_textgrid

    source = Path(args.audio)
    alignment = align(_audio(source), read_transcript(args.transcript), where=str(source))
    write_alignment_textgrid(Path(args.out), alignment)
    spoken = sum(span.phoneme != "sil" for span in alignment.phones)
    print(
        f"wrote {spoken} phones and {len(alignment.words)} words to {args.out} "
        f"(alignment confidence {alignment.confidence:.2f})"
    )


def _audio(path: Path) -> Audio:
    from ..audio import read_wav

    if path.suffix.lower() == ".wav":
        return read_wav(path)
    from ..capture.decode import media_audio

    return media_audio(path)


def read_transcript(given: str) -> str:
    """``--transcript``: the text itself, or the text of the ``.txt`` file it names."""
    path = Path(given)
    if path.suffix.lower() == ".txt" and path.is_file():
        return path.read_text(encoding="utf-8-sig")
    return given
