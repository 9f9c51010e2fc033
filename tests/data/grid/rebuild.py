"""Rebuild the GRID real-face test set from the GRID clips that ``sources.csv`` names.

    python tests/data/grid/rebuild.py rizkiarm/LipNet=DIR osalinasv/lipnet=DIR

Each ``OWNER/NAME=DIR`` gives a checkout of that repository holding the files
``sources.csv`` lists for it at the commit it lists (one row a clip: its stem, its
speaker, where its video is and, where GRID's word times came with it, its ``.align``).
It writes beside this file:

- ``swwp2s.mp4`` (H.264 + AAC), ``swwp2s.txt`` and ``swwp2s.align``: the one clip with
  pictures shipped;
- ``clips/``: each other clip's sound (``<stem>.ogg``, Opus, 16 kHz mono, 32 kbit/s) and,
  where there is one, its ``.align`` unchanged;
- ``corpus/``: ``lipstream capture`` over every clip, each transcript the sentence its
  GRID file name encodes, each clip's channels mapped through its speaker's range (the
  clips of GRID's talker ``s1`` share one, every other clip has its own), without WAVs.

A clip the capture refuses is left out, with its coded error printed.
"""

from __future__ import annotations

import csv
import shutil
import sys
import tempfile
from fractions import Fraction
from pathlib import Path

import av

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent.parent / "lipstream" / "capture"))
from grid_names import grid_words  # noqa: E402  (beside the tests)

CLIP = "swwp2s"
SOUND_RATE = 16000
SOUND_BITS_PER_S = 32000


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


def sound_only(source: Path, target: Path) -> None:
    """``source``'s sound as Opus in Ogg, mono at ``SOUND_RATE``."""
    with av.open(str(source)) as sound, av.open(str(target), "w", format="ogg") as out:
        audio = out.add_stream("libopus", rate=SOUND_RATE, layout="mono")
        audio.bit_rate = SOUND_BITS_PER_S
        mono = av.AudioResampler(format="s16", layout="mono", rate=SOUND_RATE)
        samples = 0
        frames = [*sound.decode(sound.streams.audio[0]), None]
        for sound_frame in frames:
            for piece in mono.resample(sound_frame):
                piece.pts = samples
                samples += piece.samples
                out.mux(audio.encode(piece))
        out.mux(audio.encode(None))


def read_sources() -> list[dict[str, str]]:
    with (HERE / "sources.csv").open(newline="", encoding="utf-8") as handle:
        return list(csv.DictReader(handle))


def main(checkouts: dict[str, Path]) -> None:
    from lipstream.capture.jobs import CaptureJob
    from lipstream.capture.pipeline import capture

    rows = read_sources()
    clips_dir, corpus = HERE / "clips", HERE / "corpus"
    for folder in (clips_dir, corpus):
        shutil.rmtree(folder, ignore_errors=True)
    clips_dir.mkdir()
    jobs = []
    with tempfile.TemporaryDirectory() as scratch:
        for row in rows:
            stem, video = row["stem"], checkouts[row["video_repository"]] / row["video_path"]
            text = " ".join(grid_words(stem))
            if stem == CLIP:
                transcode(video, HERE / f"{CLIP}.mp4")
                (HERE / f"{CLIP}.txt").write_text(text + "\n", encoding="utf-8")
            else:
                sound_only(video, clips_dir / f"{stem}.ogg")
            if row["align_path"]:
                align = checkouts[row["align_repository"]] / row["align_path"]
                shutil.copyfile(align, (HERE if stem == CLIP else clips_dir) / f"{stem}.align")
            copy = Path(scratch) / f"{stem}{video.suffix}"
            shutil.copyfile(video, copy)
            jobs.append(CaptureJob(copy, text, stem, row["speaker"]))
        result = capture(jobs, corpus, name="grid", report=print)
    for failure in result.failures:
        print(f"left out: {failure}", file=sys.stderr)
        for kept in clips_dir.glob(f"{Path(failure.where or '').stem}.*"):
            kept.unlink()
    for wav in corpus.glob("*.wav"):
        wav.unlink()


if __name__ == "__main__":
    given = dict(argument.split("=", 1) for argument in sys.argv[1:])
    main({repository: Path(folder) for repository, folder in given.items()})
