"""A camera and a microphone for Chromium, made from a video file.

Sketch: Chromium's fake capture devices read ``--use-file-for-fake-video-capture=<.y4m>``
(YUV4MPEG2: raw yuv420p frames, written by PyAV's ``yuv4mpegpipe`` muxer with the
``rawvideo`` codec) and ``--use-file-for-fake-audio-capture=<.wav>`` (16-bit PCM, mono).
Each starts from its file's beginning when a page opens the device, and loops, so a page
that opens both afresh for a take records the clip from its first frame.
``--use-fake-ui-for-media-stream`` is left out: a test grants (or withholds) the camera
and microphone per browser context.
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import av

SAMPLE_RATE = 44100


class FakeDevices(NamedTuple):
    camera: Path
    microphone: Path
    seconds: float

    def flags(self) -> list[str]:
        """Chromium's command-line flags that make these files its camera and microphone."""
        return [
            "--use-fake-device-for-media-stream",
            f"--use-file-for-fake-video-capture={self.camera}",
            f"--use-file-for-fake-audio-capture={self.microphone}",
        ]


def fake_devices(video: Path, directory: Path) -> FakeDevices:
    """``directory/camera.y4m`` and ``directory/microphone.wav`` from ``video``'s picture
    and sound; ``seconds`` is the picture's length."""
    camera = directory / "camera.y4m"
    microphone = directory / "microphone.wav"
    frames, rate = _write_y4m(video, camera)
    _write_wav(video, microphone)
    return FakeDevices(camera, microphone, frames / rate)


def _write_y4m(video: Path, target: Path) -> tuple[int, float]:
    """Write the picture; its frame count and frame rate."""
    with av.open(str(video)) as source, av.open(str(target), "w", format="yuv4mpegpipe") as out:
        picture = source.streams.video[0]
        rate = picture.average_rate
        if rate is None:
            raise ValueError(f"{video}: the video track declares no frame rate")
        stream = out.add_stream("rawvideo", rate=rate)
        stream.width = picture.codec_context.width
        stream.height = picture.codec_context.height
        stream.pix_fmt = "yuv420p"
        count = 0
        for frame in source.decode(picture):
            out.mux(stream.encode(frame.reformat(format="yuv420p")))
            count += 1
        out.mux(stream.encode(None))
    return count, float(rate)


def _write_wav(video: Path, target: Path) -> None:
    with av.open(str(video)) as source, av.open(str(target), "w", format="wav") as out:
        stream = out.add_stream("pcm_s16le", rate=SAMPLE_RATE, layout="mono")
        resampler = av.AudioResampler(format="s16", layout="mono", rate=SAMPLE_RATE)
        for frame in [*source.decode(source.streams.audio[0]), None]:
            for resampled in resampler.resample(frame):
                resampled.pts = None
                out.mux(stream.encode(resampled))
        out.mux(stream.encode(None))
