"""What to capture: each video with its transcript and the stem it gets in the corpus.

Sketch: arguments are video files or folders (a folder's videos are taken in name
order). One video may take ``--transcript``, as the text itself or a ``.txt`` file;
otherwise, and always for several videos, each video's transcript is the ``.txt`` file
of the same stem beside it. A missing or empty transcript is ``missing_transcript``, a
path that is neither a video nor a folder ``no_videos``, two videos of one stem
``invalid_request``, each naming the file. The videos are one speaker's unless each is
declared its own (``speaker_per_video``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from ..errors import LipstreamError
from .errors import MISSING_TRANSCRIPT, NO_VIDEOS

VIDEO_SUFFIXES = frozenset(
    {".mp4", ".m4v", ".mov", ".mkv", ".webm", ".avi", ".mpg", ".mpeg", ".ts", ".flv", ".wmv"}
)
TRANSCRIPT_SUFFIX = ".txt"


@dataclass(frozen=True)
class CaptureJob:
    """One video, its transcript, its utterance stem and its speaker (whose range its
    channels are mapped through; None: the run's one unnamed speaker)."""

    video: Path
    transcript: str
    stem: str
    speaker: str | None = None


def capture_jobs(
    arguments: Sequence[str],
    transcript: str | None,
    *,
    speaker: str | None = None,
    speaker_per_video: bool = False,
) -> list[CaptureJob]:
    """The jobs of the command's arguments; ``speaker`` names the one speaker of every
    video, ``speaker_per_video`` makes each video's stem its own speaker."""
    videos = _videos(arguments)
    if transcript is not None and len(videos) > 1:
        raise LipstreamError(
            f"--transcript goes with one video; for {len(videos)} videos put each one's "
            "transcript beside it as a .txt file of the same stem",
            where="--transcript",
            code="invalid_request",
        )
    jobs = []
    seen: dict[str, Path] = {}
    for video in videos:
        if video.stem in seen:
            raise LipstreamError(
                f"two videos share the stem {video.stem!r} ({seen[video.stem]} and {video}); "
                "each becomes one utterance of that name",
                where=str(video),
                code="invalid_request",
            )
        seen[video.stem] = video
        text = _given(transcript) if transcript is not None else _beside(video)
        if not text.strip():
            raise LipstreamError(
                "the transcript is empty", where=str(video), code=MISSING_TRANSCRIPT
            )
        who = video.stem if speaker_per_video else speaker
        jobs.append(CaptureJob(video, " ".join(text.split()), video.stem, who))
    return jobs


def _videos(arguments: Sequence[str]) -> list[Path]:
    videos: list[Path] = []
    for argument in arguments:
        path = Path(argument)
        if path.is_dir():
            found = sorted(
                child
                for child in path.iterdir()
                if child.is_file() and child.suffix.lower() in VIDEO_SUFFIXES
            )
            if not found:
                raise LipstreamError(
                    f"the folder holds no video ({', '.join(sorted(VIDEO_SUFFIXES))})",
                    where=str(path),
                    code=NO_VIDEOS,
                )
            videos.extend(found)
        elif path.is_file():
            videos.append(path)
        else:
            raise LipstreamError("no such file or folder", where=str(path), code=NO_VIDEOS)
    return videos


def _given(transcript: str) -> str:
    path = Path(transcript)
    if path.suffix.lower() == TRANSCRIPT_SUFFIX and path.is_file():
        return _read(path)
    return transcript


def _beside(video: Path) -> str:
    path = video.with_suffix(TRANSCRIPT_SUFFIX)
    if not path.is_file():
        raise LipstreamError(
            f"no transcript: expected {path.name} beside the video (or --transcript for one video)",
            where=str(video),
            code=MISSING_TRANSCRIPT,
        )
    return _read(path)


def _read(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise LipstreamError(
            "the transcript is not UTF-8 text", where=str(path), code=MISSING_TRANSCRIPT
        ) from None
