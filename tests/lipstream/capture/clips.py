"""Videos made in the tests from the shipped GRID clip: decoded once, re-encoded with
changes (no sound, pictures blanked or doubled) as H.264 + AAC in MP4."""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import av
import numpy as np

DATA = Path(__file__).resolve().parents[2] / "data" / "grid"
CLIP = DATA / "swwp2s.mp4"
FPS = 25
TIME_BASE = Fraction(1, 1000)


@dataclass(frozen=True)
class Clip:
    pictures: list[np.ndarray]  # (height, width, 3) uint8 each
    sound: np.ndarray  # mono float32
    rate: int


def read_clip(path: Path = CLIP) -> Clip:
    with av.open(str(path)) as container:
        pictures = [frame.to_ndarray(format="rgb24") for frame in container.decode(video=0)]
    with av.open(str(path)) as container:
        mono = av.AudioResampler(format="flt", layout="mono")
        pieces = [
            piece.to_ndarray().reshape(-1)
            for frame in container.decode(audio=0)
            for piece in mono.resample(frame)
        ]
        rate = container.streams.audio[0].sample_rate
    return Clip(pictures, np.concatenate(pieces), rate)


def write_clip(
    path: Path,
    pictures: list[np.ndarray],
    sound: np.ndarray | None,
    rate: int,
    times: list[Fraction] | None = None,
) -> Path:
    """An MP4 of ``pictures`` at ``times`` (s, default i / 25) and ``sound`` from 0 s."""
    height, width = pictures[0].shape[:2]
    with av.open(str(path), "w", options={"movflags": "faststart"}) as out:
        video = out.add_stream("libx264", rate=FPS, options={"crf": "18"})
        video.time_base = video.codec_context.time_base = TIME_BASE
        video.width, video.height, video.pix_fmt = width, height, "yuv420p"
        audio = out.add_stream("aac", rate=rate, layout="mono") if sound is not None else None
        for index, picture in enumerate(pictures):
            frame = av.VideoFrame.from_ndarray(picture, format="rgb24")
            at = times[index] if times is not None else Fraction(index, FPS)
            frame.pts, frame.time_base = int(at / TIME_BASE), TIME_BASE
            out.mux(video.encode(frame))
        out.mux(video.encode(None))
        if audio is not None and sound is not None:
            step = 1024
            for start in range(0, len(sound), step):
                chunk = sound[start : start + step].astype(np.float32)[None, :]
                sound_frame = av.AudioFrame.from_ndarray(chunk, format="flt", layout="mono")
                sound_frame.sample_rate, sound_frame.pts = rate, start
                out.mux(audio.encode(sound_frame))
            out.mux(audio.encode(None))
    return path
