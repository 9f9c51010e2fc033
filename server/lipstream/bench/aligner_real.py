"""The forced aligner on real recordings: its word times against GRID's own.

Method: every ``<stem>.align`` in the clips folder or below it (GRID's word times,
``start end word`` per line in units of 1/25000 s, ``sil`` and ``sp`` for silence and
short pauses) whose same-stem sound is beside it (``.wav``, else a video or sound file
PyAV decodes) is aligned by ``frontends.align`` with GRID's words as the transcript.
Each word's aligned onset and offset is compared with GRID's; the errors (aligned minus
GRID's, ms) are summarised as median, 90th percentile and maximum of their size, and
their mean (the bias), over all words and at each word position. The confidence the
aligner reports and its real-time factor (alignment seconds per second of audio, one
run, wall clock) go beside them. GRID's times sit on a 10 ms grid and pocketsphinx's on
its 10 ms frames, so no error below 10 ms is resolved. A clip the aligner refuses (a
coded error, such as ``transcript_mismatch``) is listed with its error and counted apart.

    python -m lipstream.bench.aligner_real [CLIPS_DIR] [--json bench/aligner_real.json]

``CLIPS_DIR`` defaults to the GRID clips a checkout ships (``tests/data/grid``: ``swwp2s``
beside it, the others' sound and word times in ``clips/``).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import LipstreamError
from ..results_file import recorded, script_command, write_results

MODULE = "lipstream.bench.aligner_real"
GRID_CLIPS = Path(__file__).resolve().parents[3] / "tests" / "data" / "grid"
GRID_UNITS_PER_S = 25000
GRID_PAUSES = frozenset({"sil", "sp"})
GRID_SOUND_FOLDERS = (".", "clips")
SOUND_SUFFIXES = (".wav", ".mp4", ".mpg", ".mkv", ".webm", ".mov", ".flac", ".ogg", ".mp3")


@dataclass(frozen=True)
class LabelledWord:
    word: str
    start: float
    end: float


def read_grid_align(path: Path) -> list[LabelledWord]:
    """GRID's words of one ``.align`` file in seconds, silences and pauses left out."""
    words = []
    for line in path.read_text(encoding="utf-8").splitlines():
        if not line.strip():
            continue
        start, end, word = line.split()
        if word not in GRID_PAUSES:
            words.append(
                LabelledWord(word, int(start) / GRID_UNITS_PER_S, int(end) / GRID_UNITS_PER_S)
            )
    return words


def sound_beside(align_file: Path) -> Path | None:
    """The first same-stem file that holds the clip's sound, in ``SOUND_SUFFIXES`` order."""
    for suffix in SOUND_SUFFIXES:
        candidate = align_file.with_suffix(suffix)
        if candidate.is_file():
            return candidate
    return None


def grid_sound(grid_dir: Path, stem: str) -> Path | None:
    """The sound of the shipped GRID clip ``stem``: its same-stem file in ``grid_dir`` or
    its ``clips/`` folder (``GRID_SOUND_FOLDERS``), in ``SOUND_SUFFIXES`` order."""
    for folder in GRID_SOUND_FOLDERS:
        found = sound_beside(grid_dir / folder / f"{stem}.align")
        if found is not None:
            return found
    return None


def read_sound(path: Path) -> Any:
    from ..audio import read_wav

    if path.suffix.lower() == ".wav":
        return read_wav(path)
    from ..capture.decode import media_audio

    return media_audio(path)


def _summary(errors_ms: Sequence[float]) -> dict[str, float]:
    sizes = np.abs(np.asarray(errors_ms, dtype=np.float64))
    return {
        "median_ms": round(float(np.median(sizes)), 1),
        "p90_ms": round(float(np.percentile(sizes, 90)), 1),
        "max_ms": round(float(sizes.max()), 1),
        "mean_signed_ms": round(float(np.mean(errors_ms)), 1),
    }


def measure_clip(align_file: Path, sound: Path) -> dict[str, Any]:
    """One clip: per word GRID's and the aligner's times, and the errors' summaries."""
    from ..frontends.align import align

    truth = read_grid_align(align_file)
    audio = read_sound(sound)
    began = time.perf_counter()
    alignment = align(audio, " ".join(word.word for word in truth), where=str(sound))
    seconds = time.perf_counter() - began
    found = alignment.words
    if [word.word for word in found] != [word.word for word in truth]:
        raise LipstreamError(
            "the aligner's words are not GRID's", where=str(sound), code="transcript_mismatch"
        )
    onsets = [1000 * (a.start - b.start) for a, b in zip(found, truth)]
    offsets = [1000 * (a.end - b.end) for a, b in zip(found, truth)]
    return {
        "clip": align_file.stem,
        "sound": sound.name,
        "audio_s": round(audio.duration, 3),
        "confidence": round(alignment.confidence, 3),
        "real_time_factor": round(seconds / audio.duration, 3),
        "words": [
            {
                "word": b.word,
                "grid_s": [round(b.start, 3), round(b.end, 3)],
                "aligned_s": [round(a.start, 3), round(a.end, 3)],
            }
            for a, b in zip(found, truth)
        ],
        "onset": _summary(onsets),
        "offset": _summary(offsets),
        "onset_errors_ms": [round(error, 1) for error in onsets],
        "offset_errors_ms": [round(error, 1) for error in offsets],
    }


def run(clips_dir: Path, command: str) -> dict[str, Any]:
    clips, refused = [], []
    for align_file in sorted(clips_dir.rglob("*.align"), key=lambda path: path.stem):
        sound = sound_beside(align_file)
        if sound is None:
            continue
        try:
            clips.append(measure_clip(align_file, sound))
        except LipstreamError as error:
            refused.append({"clip": align_file.stem, "code": error.code, "error": error.message})
    if not clips:
        raise SystemExit(f"{clips_dir}: no .align file with its sound beside it")
    onsets = [error for clip in clips for error in clip["onset_errors_ms"]]
    offsets = [error for clip in clips for error in clip["offset_errors_ms"]]
    return {
        **recorded(command),
        "clips_dir": clips_dir.name,
        "reference": "GRID's word times (.align, 1/25000 s units, on a 10 ms grid)",
        "clips": clips,
        "refused": refused,
        "all": {
            "clips": len(clips),
            "refused": len(refused),
            "words": len(onsets),
            "onset": _summary(onsets),
            "offset": _summary(offsets),
            "onset_by_position": by_position(clips, "onset_errors_ms"),
        },
    }


def by_position(clips: Sequence[dict[str, Any]], key: str) -> list[dict[str, float]]:
    """The summary of ``key``'s errors at each word position (GRID's sentences are six
    words: command, colour, preposition, letter, digit, adverb); empty unless every clip
    has as many words."""
    counts = {len(clip[key]) for clip in clips}
    if len(counts) != 1:
        return []
    return [_summary([clip[key][i] for clip in clips]) for i in range(counts.pop())]


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("clips", nargs="?", type=Path, default=GRID_CLIPS)
    parser.add_argument("--json", type=Path, help="write the results here")
    args = parser.parse_args(argv)
    results = run(args.clips, script_command(MODULE, argv))
    if args.json is not None:
        write_results(results, args.json)
    for clip in results["clips"]:
        on, off = clip["onset"], clip["offset"]
        print(
            f"{clip['clip']}: onsets |error| median {on['median_ms']} p90 {on['p90_ms']} max "
            f"{on['max_ms']} ms; offsets {off['median_ms']} / {off['p90_ms']} / "
            f"{off['max_ms']} ms; confidence {clip['confidence']}",
            file=sys.stderr,
        )
    for refusal in results["refused"]:
        print(
            f"{refusal['clip']}: refused: {refusal['error']} [{refusal['code']}]", file=sys.stderr
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
