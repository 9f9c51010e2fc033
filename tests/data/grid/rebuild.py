"""Rebuild the GRID real-face test set from the GRID clips in rizkiarm/LipNet.

    python tests/data/grid/rebuild.py SAMPLES_DIR

``SAMPLES_DIR`` holds ``evaluation/samples/GRID/*.mpg``, ``id2_vcd_swwp2s.mpg`` and
``swwp2s.align`` of https://github.com/rizkiarm/LipNet (commit bec592a). It writes
``swwp2s.mp4`` (the one clip shipped, H.264 + AAC), ``swwp2s.txt`` and ``swwp2s.align``
beside this file, and ``corpus/``: ``lipstream capture`` over the eleven clips, each its
own speaker, with each clip's transcript from its GRID file name, without the WAVs.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
from fractions import Fraction
from pathlib import Path

import av

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent.parent / "lipstream" / "capture"))
from grid_names import grid_words  # noqa: E402  (beside the tests)

CLIP = "swwp2s"


def transcode(source: Path, target: Path) -> None:
    """``source`` as H.264 (CRF 23, its own frame rate) + AAC (mono) in MP4."""
    with (
        av.open(str(source)) as pictures,
        av.open(str(source)) as sound,
        av.open(str(target), "w", options={"movflags": "faststart"}) as out,
    ):
        video_in, audio_in = pictures.streams.video[0], sound.streams.audio[0]
        video = out.add_stream("libx264", rate=video_in.average_rate, options={"crf": "23"})
        video.width, video.height, video.pix_fmt = video_in.width, video_in.height, "yuv420p"
        audio = out.add_stream("aac", rate=audio_in.sample_rate, layout="mono")
        mono = av.AudioResampler(format="fltp", layout="mono", rate=audio_in.sample_rate)
        rate = video_in.average_rate
        if rate is None:
            raise ValueError(f"{source}: the video stream has no average frame rate")
        for index, frame in enumerate(pictures.decode(video_in)):
            frame.pts, frame.time_base = index, 1 / Fraction(rate)
            out.mux(video.encode(frame))
        out.mux(video.encode(None))
        samples = 0
        for sound_frame in sound.decode(audio_in):
            for piece in mono.resample(sound_frame):
                piece.pts = samples  # in samples: the encoder's time base is 1 / sample rate
                samples += piece.samples
                out.mux(audio.encode(piece))
        out.mux(audio.encode(None))


def main(samples: Path) -> None:
    shutil.copyfile(samples / "swwp2s.align", HERE / "swwp2s.align")
    transcode(samples / "id2_vcd_swwp2s.mpg", HERE / f"{CLIP}.mp4")
    (HERE / f"{CLIP}.txt").write_text(" ".join(grid_words(CLIP)) + "\n", encoding="utf-8")
    corpus = HERE / "corpus"
    shutil.rmtree(corpus, ignore_errors=True)
    with tempfile.TemporaryDirectory() as scratch:
        clips = Path(scratch)
        for video in sorted((samples / "GRID").glob("*.mpg")):
            shutil.copyfile(video, clips / video.name)
            text = " ".join(grid_words(video.stem))
            (clips / f"{video.stem}.txt").write_text(text + "\n", encoding="utf-8")
        shutil.copyfile(samples / "id2_vcd_swwp2s.mpg", clips / f"{CLIP}.mpg")
        (clips / f"{CLIP}.txt").write_text(" ".join(grid_words(CLIP)) + "\n", encoding="utf-8")
        command = [sys.executable, "-m", "lipstream.cli", "capture", str(clips)]
        command += ["--out", str(corpus), "--name", "grid", "--speaker-per-video"]
        subprocess.run(command, check=True)
    for wav in corpus.glob("*.wav"):
        wav.unlink()


if __name__ == "__main__":
    main(Path(sys.argv[1]))
