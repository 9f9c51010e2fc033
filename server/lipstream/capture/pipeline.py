"""One capture run: videos and transcripts in, a lipstream corpus out.

Sketch: each video is decoded (``decode``), its face tracked (``track``), checked for one
face and its short gaps bridged (``gaps``), its pose removed (``pose``) and its speech
aligned to the transcript (``frontends.align``). Then every clip's measures are taken
against its own rest pose and mapped to [0, 1] through its speaker's ranges over all of
that speaker's videos (``channels``; one speaker per run unless each video is declared
its own), resampled from the video's frame times onto
the corpus grid (``round(1 / median frame step)`` of the first video, as the corpus
loader does) and written with ``write_corpus``: frames CSV, TextGrid, WAV and metadata
with the transcript and the alignment's confidence. A video that fails is reported with
its coded error and the others are still written; nothing is written over an existing
corpus.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..audio import Audio
from ..corpus import Corpus, Utterance, write_corpus
from ..corpus.grid import estimate_fps, grid_size, resample_to_grid
from ..corpus.layout import is_corpus_file
from ..errors import CorpusError, LipstreamError
from ..frontends.align import Alignment, align
from ..phonemes import SILENCE
from ..timeline import PhonemeSpan
from .channels import CHANNELS, raw_measures, rest_pose, speaker_ranges, to_channels
from .decode import read_audio, read_frames, video_start
from .gaps import bridge_gaps, check_faces
from .jobs import CaptureJob
from .pose import face_frame
from .track import Track, track_faces


@dataclass(frozen=True)
class TrackedClip:
    """One video, tracked and aligned: ``times`` (n,) s, ``face`` (n, 468, 3) pose-free
    landmarks in face-scale units, the audio and its alignment."""

    job: CaptureJob
    times: np.ndarray
    face: np.ndarray
    audio: Audio
    alignment: Alignment


@dataclass
class CaptureResult:
    """What a run wrote (``corpus`` None when nothing could be) and every failure."""

    corpus: Corpus | None
    failures: list[LipstreamError] = field(default_factory=list)


def tracked_video(video: Path, where: str) -> tuple[Audio, Track]:
    """Decode one video's sound and track its face, checked and with short gaps bridged;
    coded errors name ``where``."""
    origin = video_start(video)
    audio = read_audio(video, origin)
    track = track_faces(read_frames(video))
    if len(track.times) < 2:
        raise LipstreamError(
            f"the video holds {len(track.times)} frame(s); capture needs at least two",
            where=where,
            code="corrupt_video",
        )
    check_faces(track, where)
    return audio, bridge_gaps(track, where)


def track_clip(job: CaptureJob) -> TrackedClip:
    """Decode, track, check and align one video; coded errors name the video."""
    where = str(job.video)
    audio, track = tracked_video(job.video, where)
    alignment = align(audio, job.transcript, where=where)
    return TrackedClip(job, track.times, face_frame(track.landmarks), audio, alignment)


def clips_corpus(clips: Sequence[TrackedClip], name: str) -> Corpus:
    """The corpus of ``clips``, each clip's channels mapped through its speaker's ranges."""
    measures = []
    for clip in clips:
        quiet = _in_silence(clip.times, clip.alignment.phones)
        measures.append(raw_measures(clip.face, rest_pose(clip.face, quiet)))
    speakers = {clip.job.speaker for clip in clips}
    ranges = {
        who: speaker_ranges(
            [measure for clip, measure in zip(clips, measures) if clip.job.speaker == who]
        )
        for who in speakers
    }
    fps = estimate_fps(clips[0].times, str(clips[0].job.video))
    utterances = []
    for clip, measure in zip(clips, measures, strict=True):
        channels = to_channels(measure, ranges[clip.job.speaker])
        frames = resample_to_grid(clip.times, channels, fps)
        end = (grid_size(float(clip.times[-1]), fps) - 1) / fps
        utterances.append(
            Utterance(
                stem=clip.job.stem,
                frames=frames,
                phones=_phones_until(clip.alignment.phones, end),
                fps=fps,
                audio=clip.audio,
                speaker=clip.job.speaker,
                text=clip.job.transcript,
                alignment_confidence=clip.alignment.confidence,
            )
        )
    return Corpus(name, fps, CHANNELS, utterances)


def capture(
    jobs: Sequence[CaptureJob],
    out: Path,
    *,
    name: str | None = None,
    report: Callable[[str], None] = lambda line: None,
) -> CaptureResult:
    """Capture every job into the corpus directory ``out``; the failures are returned."""
    _check_target(out)
    clips: list[TrackedClip] = []
    failures: list[LipstreamError] = []
    for index, job in enumerate(jobs, start=1):
        try:
            clip = track_clip(job)
        except LipstreamError as error:
            failures.append(error)
            report(f"[{index}/{len(jobs)}] {job.video}: refused: {error.message} [{error.code}]")
            continue
        clips.append(clip)
        report(
            f"[{index}/{len(jobs)}] {job.video}: {len(clip.times)} frames, "
            f"alignment confidence {clip.alignment.confidence:.2f}"
        )
    if not clips:
        return CaptureResult(None, failures)
    corpus = clips_corpus(clips, name or out.name)
    write_corpus(corpus, out)
    return CaptureResult(corpus, failures)


def _check_target(out: Path) -> None:
    """Refuse, before any work, a target that ``write_corpus`` would refuse after it."""
    if out.exists() and not out.is_dir():
        raise CorpusError("exists and is not a directory", where=str(out))
    if out.is_dir() and any(is_corpus_file(path) for path in out.iterdir()):
        raise CorpusError(
            "already holds corpus files; capture writes into an empty or new directory",
            where=str(out),
        )


def _in_silence(times: np.ndarray, phones: Sequence[PhonemeSpan]) -> np.ndarray:
    quiet = np.zeros(len(times), dtype=bool)
    for span in phones:
        if span.phoneme == SILENCE:
            quiet |= (times >= span.start) & (times < span.end)
    return quiet


def _phones_until(phones: Sequence[PhonemeSpan], end: float) -> list[PhonemeSpan]:
    """``phones`` cut at ``end`` s (the last frame), silence added when they stop short."""
    kept = [
        PhonemeSpan(span.phoneme, span.start, min(span.end, end))
        for span in phones
        if span.start < end
    ]
    if kept[-1].end < end:
        if kept[-1].phoneme == SILENCE:
            kept[-1] = PhonemeSpan(SILENCE, kept[-1].start, end)
        else:
            kept.append(PhonemeSpan(SILENCE, kept[-1].end, end))
    return kept
