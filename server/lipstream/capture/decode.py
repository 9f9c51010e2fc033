"""Decoding a video with PyAV: its frames at their own times, and its sound.

Sketch: frames are decoded in order and each keeps its presentation time (pts times the
stream's time base), so a variable frame rate is kept as it is; times count from the
first frame. The audio track is resampled by PyAV to mono float32 at its own sample
rate and put on the same clock (samples before the first video frame are dropped, a
late audio start is padded with silence). A file PyAV cannot open, one whose decoding
stops with an error, and one whose streams end well before their declared duration
(a truncated file) are ``corrupt_video``; a file without a video or an audio track is
``no_video_track`` or ``no_audio_track``.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..audio import Audio
from ..errors import LipstreamError
from .errors import CORRUPT_VIDEO, NO_AUDIO_TRACK, NO_VIDEO_TRACK

# A stream that ends more than this short of its declared duration was cut off.
TRUNCATION_TOLERANCE_S = 0.25


@dataclass(frozen=True)
class VideoFrame:
    """One decoded picture: ``time`` in s from the first frame, ``rgb`` (height, width, 3)
    uint8."""

    time: float
    rgb: np.ndarray


def _av() -> Any:
    from .dependencies import require

    return require("av")


def _open(path: Path) -> Any:
    av = _av()

    try:
        return av.open(str(path))
    except (av.error.FFmpegError, UnicodeDecodeError, ValueError) as error:
        raise LipstreamError(
            f"not a video PyAV can open ({error})", where=str(path), code=CORRUPT_VIDEO
        ) from None


def video_start(path: Path) -> float:
    """The presentation time of the first video frame, in s (the capture's clock zero)."""
    for frame in _decoded(path, "video"):
        return float(frame.time)
    raise LipstreamError("the video track holds no frames", where=str(path), code=CORRUPT_VIDEO)


def read_frames(path: Path) -> Iterator[VideoFrame]:
    """The video's frames in order, at their own times from the first frame."""
    origin: float | None = None
    for frame in _decoded(path, "video"):
        origin = float(frame.time) if origin is None else origin
        yield VideoFrame(float(frame.time) - origin, frame.to_ndarray(format="rgb24"))
    if origin is None:
        raise LipstreamError("the video track holds no frames", where=str(path), code=CORRUPT_VIDEO)


def read_audio(path: Path, origin: float) -> Audio:
    """The audio track, mono float32 at its own rate, from ``origin`` (s) on."""
    av = _av()

    resampler: Any = None
    chunks: list[np.ndarray] = []
    start: float | None = None
    rate = 0
    for frame in _decoded(path, "audio"):
        if resampler is None:
            rate = int(frame.sample_rate)
            resampler = av.AudioResampler(format="flt", layout="mono", rate=rate)
            start = float(frame.time) if frame.time is not None else origin
        for mono in resampler.resample(frame):
            chunks.append(mono.to_ndarray().reshape(-1))
    if resampler is None or start is None:
        raise LipstreamError("the audio track holds no sound", where=str(path), code=CORRUPT_VIDEO)
    for mono in resampler.resample(None):
        chunks.append(mono.to_ndarray().reshape(-1))
    samples = np.concatenate(chunks).astype(np.float32)
    shift = int(round((start - origin) * rate))
    if shift > 0:
        samples = np.concatenate([np.zeros(shift, np.float32), samples])
    elif shift < 0:
        samples = samples[-shift:]
    return Audio(np.clip(samples, -1.0, 1.0), rate)


def media_audio(path: Path) -> Audio:
    """The sound of a video (on the video's clock) or of a sound file (from its start)."""
    with _open(path) as container:
        has_video = bool(container.streams.video)
    return read_audio(path, video_start(path) if has_video else _audio_start(path))


def _audio_start(path: Path) -> float:
    for frame in _decoded(path, "audio"):
        return float(frame.time or 0.0)
    return 0.0


def _decoded(path: Path, kind: str) -> Iterator[Any]:
    av = _av()

    container = _open(path)
    with container:
        streams = container.streams.video if kind == "video" else container.streams.audio
        if not streams:
            code = NO_VIDEO_TRACK if kind == "video" else NO_AUDIO_TRACK
            raise LipstreamError(f"the file has no {kind} track", where=str(path), code=code)
        stream = streams[0]
        last = None
        try:
            for frame in container.decode(stream):
                if frame.time is not None:
                    last = float(frame.time) + _frame_length(frame)
                yield frame
        except av.error.FFmpegError as error:
            raise LipstreamError(
                f"decoding the {kind} stopped at {last or 0.0:.3f} s: {error}",
                where=str(path),
                code=CORRUPT_VIDEO,
            ) from None
        _check_complete(path, kind, stream, last)


def _frame_length(frame: Any) -> float:
    rate = getattr(frame, "sample_rate", None)
    return float(frame.samples) / rate if rate else 0.0


def _check_complete(path: Path, kind: str, stream: Any, last: float | None) -> None:
    if stream.duration is None or stream.time_base is None or last is None:
        return
    declared = float((stream.start_time or 0) * stream.time_base) + float(
        stream.duration * stream.time_base
    )
    if last < declared - TRUNCATION_TOLERANCE_S:
        raise LipstreamError(
            f"the {kind} ends at {last:.2f} s but the file declares {declared:.2f} s: "
            "the file is truncated",
            where=str(path),
            code=CORRUPT_VIDEO,
        )
