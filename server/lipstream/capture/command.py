"""The ``lipstream capture`` command: its options and its run.

Sketch: ``lipstream capture VIDEO... --transcript TEXT|FILE --out CORPUS_DIR`` captures
each video (``pipeline``) into a new corpus; a folder stands for its videos, each with
its same-stem ``.txt`` transcript. Progress goes to stderr, one line per video with its
alignment confidence. A refused video is reported with its coded error; the others are
written, and the command then exits 2 (one failure is raised as itself, several as
``capture_failed`` listing each). Building the parser imports nothing of the capture.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..config import Settings
from ..errors import LipstreamError

CAPTURE_FAILED = "capture_failed"


def add_capture_parser(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    capture = commands.add_parser(
        "capture",
        help="a corpus from video of a person talking: face channels, aligned phones, audio",
    )
    capture.add_argument(
        "videos",
        nargs="+",
        metavar="VIDEO",
        help="video files, or folders of them (each with a same-stem .txt transcript)",
    )
    capture.add_argument(
        "--transcript",
        help="with one video: its transcript, as text or a .txt file "
        "(default: the .txt of the video's stem beside it)",
    )
    capture.add_argument("--out", required=True, help="corpus directory to write (new or empty)")
    capture.add_argument("--name", help="corpus name (default: the --out directory's name)")
    who = capture.add_mutually_exclusive_group()
    who.add_argument("--speaker", help="the speaker's name, written in each utterance's metadata")
    who.add_argument(
        "--speaker-per-video",
        action="store_true",
        help="each video is a different speaker (named by its stem), with its own range",
    )
    capture.set_defaults(run=run_capture)


def run_capture(args: argparse.Namespace, settings: Settings) -> None:
    from .dependencies import require_capture_extra
    from .jobs import capture_jobs
    from .pipeline import capture

    require_capture_extra()
    jobs = capture_jobs(
        args.videos,
        args.transcript,
        speaker=args.speaker,
        speaker_per_video=args.speaker_per_video,
    )
    out = Path(args.out)
    result = capture(jobs, out, name=args.name, report=_to_stderr)
    if result.corpus is not None:
        corpus = result.corpus
        print(
            f"wrote {len(corpus)} utterances to {out} ({len(corpus.channels)} channels at "
            f"{corpus.fps:g} fps); train with: lipstream train --corpus {out} --engine all "
            "--out MODELS"
        )
    if len(result.failures) == 1:
        raise result.failures[0]
    if result.failures:
        listed = "".join(f"\n  {failure}" for failure in result.failures)
        raise LipstreamError(
            f"{len(result.failures)} of {len(jobs)} videos refused:{listed}",
            where=str(out),
            code=CAPTURE_FAILED,
        )


def _to_stderr(line: str) -> None:
    print(line, file=sys.stderr, flush=True)
