"""Every coded error of ``lipstream capture``, each naming the file and what is wrong,
on videos made from the shipped GRID clip; and nothing lost: the good videos of a run are
written, an existing corpus is never written over."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from lipstream.cli import main
from lipstream.corpus import load_corpus
from tests.lipstream.capture.clips import CLIP, DATA, Clip, read_clip, write_clip

TRANSCRIPT = "set white with p two soon"


@pytest.fixture(scope="module")
def clip() -> Clip:
    return read_clip()


def refused(capsys: pytest.CaptureFixture[str], args: list[str], code: str, where: Path) -> str:
    """The one ``error [code]: where: message`` line a refused run prints; exit code 2."""
    assert main(["capture", *args]) == 2
    lines = [line for line in capsys.readouterr().err.splitlines() if line.startswith("error [")]
    assert len(lines) == 1 and lines[0].startswith(f"error [{code}]: {where}: "), lines
    return lines[0]


def test_a_file_that_is_no_video_is_corrupt(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "noise.mp4"
    bad.write_bytes(np.random.default_rng(0).bytes(20000))
    refused(
        capsys,
        [str(bad), "--transcript", TRANSCRIPT, "--out", str(tmp_path / "c")],
        "corrupt_video",
        bad,
    )
    assert not (tmp_path / "c").exists()


def test_a_truncated_file_is_corrupt(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cut = tmp_path / "cut.mp4"
    cut.write_bytes(CLIP.read_bytes()[: CLIP.stat().st_size * 6 // 10])
    line = refused(
        capsys,
        [str(cut), "--transcript", TRANSCRIPT, "--out", str(tmp_path / "c")],
        "corrupt_video",
        cut,
    )
    assert "stopped at" in line or "truncated" in line


def test_a_video_without_sound_is_refused(
    clip: Clip, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    silent = write_clip(tmp_path / "mute.mp4", clip.pictures, None, clip.rate)
    refused(
        capsys,
        [str(silent), "--transcript", TRANSCRIPT, "--out", str(tmp_path / "c")],
        "no_audio_track",
        silent,
    )


def test_no_face_gives_the_share_of_frames(
    clip: Clip, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    grey = [np.full_like(picture, 128) for picture in clip.pictures]
    for index in range(0, 75, 5):  # a face in 15 of 75 frames
        grey[index] = clip.pictures[index]
    video = write_clip(tmp_path / "empty.mp4", grey, clip.sound, clip.rate)
    line = refused(
        capsys,
        [str(video), "--transcript", TRANSCRIPT, "--out", str(tmp_path / "c")],
        "no_face",
        video,
    )
    assert "20% of 75 frames" in line


def test_two_faces_are_refused(
    clip: Clip, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    pair = [np.hstack([picture, picture]) for picture in clip.pictures]
    video = write_clip(tmp_path / "pair.mp4", pair, clip.sound, clip.rate)
    line = refused(
        capsys,
        [str(video), "--transcript", TRANSCRIPT, "--out", str(tmp_path / "c")],
        "several_faces",
        video,
    )
    assert "of 75 frames show more than one face" in line


def test_a_long_tracking_gap_is_refused_and_a_short_one_bridged(
    clip: Clip, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    long_gap = list(clip.pictures)
    for index in range(30, 35):  # 200 ms without a face
        long_gap[index] = np.full_like(clip.pictures[index], 128)
    video = write_clip(tmp_path / "gap.mp4", long_gap, clip.sound, clip.rate)
    line = refused(
        capsys,
        [str(video), "--transcript", TRANSCRIPT, "--out", str(tmp_path / "c")],
        "tracking_gap",
        video,
    )
    assert "from 1.20 s to 1.40 s" in line
    short_gap = list(clip.pictures)
    for index in (30, 31):  # 80 ms
        short_gap[index] = np.full_like(clip.pictures[index], 128)
    video = write_clip(tmp_path / "blink.mp4", short_gap, clip.sound, clip.rate)
    assert (
        main(["capture", str(video), "--transcript", TRANSCRIPT, "--out", str(tmp_path / "ok")])
        == 0
    )
    assert load_corpus(tmp_path / "ok").utterances[0].n_frames == 75


def test_a_transcript_of_other_words_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    refused(
        capsys,
        [str(CLIP), "--transcript", "bin blue at f two now", "--out", str(tmp_path / "c")],
        "transcript_mismatch",
        CLIP,
    )


def test_a_video_without_its_transcript_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    video = tmp_path / "alone.mp4"
    shutil.copyfile(CLIP, video)
    refused(capsys, [str(video), "--out", str(tmp_path / "c")], "missing_transcript", video)


def test_nothing_is_lost_the_good_videos_are_written_and_the_bad_one_named(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "takes"
    folder.mkdir()
    shutil.copyfile(CLIP, folder / "good.mp4")
    shutil.copyfile(DATA / "swwp2s.txt", folder / "good.txt")
    (folder / "broken.mp4").write_bytes(b"\x00" * 4096)
    (folder / "broken.txt").write_text(TRANSCRIPT)
    refused(
        capsys, [str(folder), "--out", str(tmp_path / "c")], "corrupt_video", folder / "broken.mp4"
    )
    assert load_corpus(tmp_path / "c").stems == ("good",)
    # A second run never writes over the corpus it made.
    before = sorted(path.name for path in (tmp_path / "c").iterdir())
    refused(
        capsys,
        [str(folder / "good.mp4"), "--out", str(tmp_path / "c")],
        "corpus_invalid",
        tmp_path / "c",
    )
    assert sorted(path.name for path in (tmp_path / "c").iterdir()) == before


def test_several_refused_videos_are_listed_each_with_its_code(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "takes"
    folder.mkdir()
    for stem in ("a", "b"):
        (folder / f"{stem}.mp4").write_bytes(b"\x00" * 4096)
        (folder / f"{stem}.txt").write_text(TRANSCRIPT)
    assert main(["capture", str(folder), "--out", str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err
    assert f"error [capture_failed]: {tmp_path / 'c'}: 2 of 2 videos refused:" in err
    assert f"{folder / 'a.mp4'}: not a video" in err and f"{folder / 'b.mp4'}: not a video" in err
    assert not (tmp_path / "c").exists()
