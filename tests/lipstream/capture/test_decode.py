"""Decoding keeps each frame's own time (a variable frame rate stays as written) and puts
the sound on the pictures' clock."""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from lipstream.capture.decode import read_audio, read_frames, video_start
from lipstream.cli import main
from lipstream.corpus import load_corpus
from tests.lipstream.capture.clips import read_clip, write_clip


def test_a_variable_frame_rate_keeps_its_own_frame_times(tmp_path: Path) -> None:
    clip = read_clip()
    # Steps of 30, 40 and 50 ms in turn: no constant rate describes them.
    steps = [Fraction(30 + 10 * (i % 3), 1000) for i in range(len(clip.pictures))]
    times = [sum(steps[:i], Fraction(0)) for i in range(len(clip.pictures))]
    video = write_clip(tmp_path / "vfr.mp4", clip.pictures, clip.sound, clip.rate, times)
    found = [frame.time for frame in read_frames(video)]
    np.testing.assert_allclose(found, [float(t) for t in times], atol=1e-9)


def test_a_late_first_picture_is_the_clock_zero_of_the_sound(tmp_path: Path) -> None:
    clip = read_clip()
    times = [Fraction(200, 1000) + Fraction(i, 25) for i in range(len(clip.pictures))]
    video = write_clip(tmp_path / "late.mp4", clip.pictures, clip.sound, clip.rate, times)
    origin = video_start(video)
    assert origin == pytest.approx(0.2, abs=1e-6)
    sound = read_audio(video, origin)
    whole = read_audio(video, 0.0)
    # The first 0.2 s of sound are before the first picture, so they are dropped.
    assert len(whole.samples) - len(sound.samples) == round(0.2 * clip.rate)
    np.testing.assert_array_equal(
        sound.samples[:1000], whole.samples[round(0.2 * clip.rate) :][:1000]
    )


def test_a_variable_rate_video_captures_onto_the_median_step_grid(tmp_path: Path) -> None:
    clip = read_clip()
    steps = [Fraction(36 if i % 2 else 44, 1000) for i in range(len(clip.pictures))]
    times = [sum(steps[:i], Fraction(0)) for i in range(len(clip.pictures))]
    video = write_clip(tmp_path / "vfr.mp4", clip.pictures, clip.sound, clip.rate, times)
    out = tmp_path / "c"
    assert (
        main(
            ["capture", str(video), "--transcript", "set white with p two soon", "--out", str(out)]
        )
        == 0
    )
    [utterance] = load_corpus(out).utterances
    assert utterance.fps == 25.0  # round(1 / median(36 ms, 44 ms))
    assert utterance.duration == pytest.approx(float(times[-1]), abs=1 / 25)
