"""The forced aligner on a real recording: the shipped GRID clip's sound (read here with
PyAV, not through lipstream) aligned to its sentence, its word times against GRID's own
(``swwp2s.align``, units of 1/25000 s), which no code of ours made.

The tolerances come from the measurement (``bench/aligner_real.json``,
``python -m lipstream.bench.aligner_real``): onsets measured 10 to 50 ms from GRID's
(median 25), offsets 10 to 40 ms (median 25). Each bound adds one 10 ms frame of
pocketsphinx's to what was measured, since both time grids are 10 ms: a word moved by one
more frame passes, one moved by two fails.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from lipstream.audio import Audio, write_wav
from lipstream.bench.aligner_real import main as bench_main
from lipstream.bench.aligner_real import read_grid_align
from lipstream.frontends.align import align
from tests.lipstream.capture.clips import CLIP, DATA, read_clip

pytestmark = pytest.mark.skipif(shutil.which("espeak-ng") is None, reason="espeak-ng missing")

GRID_UNITS_PER_S = 25000  # GRID's .align: 1000 units per 40 ms video frame
MAX_ONSET_MS, MEDIAN_ONSET_MS = 60.0, 35.0
MAX_OFFSET_MS, MEDIAN_OFFSET_MS = 50.0, 35.0


def grid_words() -> list[tuple[str, float, float]]:
    rows = [line.split() for line in (DATA / "swwp2s.align").read_text().splitlines()]
    return [(w, int(a) / GRID_UNITS_PER_S, int(b) / GRID_UNITS_PER_S) for a, b, w in rows]


def test_grids_units_are_25000_a_second() -> None:
    """GRID's clips last 3 s (75 frames at 25 fps): the last label ends just before."""
    last_end = grid_words()[-1][2]
    clip = read_clip()
    assert len(clip.pictures) == 75
    assert 2.9 <= last_end <= len(clip.sound) / clip.rate <= 3.05


def test_word_times_on_grids_clip_are_within_a_frame_of_the_measured_errors() -> None:
    clip = read_clip(CLIP)
    audio = Audio(clip.sound.astype(np.float64), clip.rate)
    transcript = (DATA / "swwp2s.txt").read_text(encoding="utf-8")
    alignment = align(audio, transcript, where=str(CLIP))
    truth = [word for word in grid_words() if word[0] != "sil"]
    assert [w.word for w in alignment.words] == [word for word, _, _ in truth]
    onsets = np.array([1000 * abs(w.start - t[1]) for w, t in zip(alignment.words, truth)])
    offsets = np.array([1000 * abs(w.end - t[2]) for w, t in zip(alignment.words, truth)])
    assert onsets.max() <= MAX_ONSET_MS and np.median(onsets) <= MEDIAN_ONSET_MS, onsets
    assert offsets.max() <= MAX_OFFSET_MS and np.median(offsets) <= MEDIAN_OFFSET_MS, offsets
    assert 0.25 <= alignment.confidence <= 1.0


def test_the_bench_reports_errors_against_grids_times(tmp_path: Path) -> None:
    """The bench over a folder with the clip: its errors are its aligned times minus
    GRID's, read from the .align here; a folder's .align without sound is passed over."""
    for name in ("swwp2s.mp4", "swwp2s.align"):
        shutil.copyfile(DATA / name, tmp_path / name)
    (tmp_path / "lonely.align").write_text("0 1000 sil\n1000 9000 bin\n", encoding="utf-8")
    out = tmp_path / "out.json"
    assert bench_main([str(tmp_path), "--json", str(out)]) == 0
    results = json.loads(out.read_text(encoding="utf-8"))
    assert {"machine", "date", "command"} <= set(results)
    [clip] = results["clips"]
    truth = [word for word in grid_words() if word[0] != "sil"]
    assert [row["word"] for row in clip["words"]] == [word for word, _, _ in truth]
    expected = [1000 * (row["aligned_s"][0] - t[1]) for row, t in zip(clip["words"], truth)]
    assert clip["onset_errors_ms"] == pytest.approx(expected, abs=0.6)
    sizes = np.abs(expected)
    assert clip["onset"]["max_ms"] == pytest.approx(sizes.max(), abs=0.6)
    assert clip["onset"]["median_ms"] == pytest.approx(np.median(sizes), abs=0.6)
    assert results["all"]["words"] == len(truth)


def test_grids_pauses_are_not_words(tmp_path: Path) -> None:
    path = tmp_path / "lbaq5s.align"
    path.write_text("0 4000 sil\n4000 20500 lay\n20500 28750 sp\n28750 31250 at\n", "utf-8")
    assert [(w.word, w.start, w.end) for w in read_grid_align(path)] == [
        ("lay", 0.16, 0.82),
        ("at", 1.15, 1.25),
    ]


# three clips of talker s1 with GRID's times and their sound (Opus) in clips/; each
# bound is one 10 ms frame over what was measured on them (bench/aligner_real.json)
CLIPS_ALIGNED = ("bgbu5a", "pgij9s", "srbb5s")
CLIPS_MAX_ONSET_MS, CLIPS_MEDIAN_ONSET_MS = 50.0, 20.0


def test_the_bench_finds_clips_below_the_folder_and_lists_refusals(tmp_path: Path) -> None:
    """Clips in a subfolder are measured against GRID's times read here; a clip whose
    sound is silent is listed as refused with its code, and the others go on."""
    clips = tmp_path / "clips"
    clips.mkdir()
    for stem in CLIPS_ALIGNED:
        for suffix in (".ogg", ".align"):
            shutil.copyfile(DATA / "clips" / f"{stem}{suffix}", clips / f"{stem}{suffix}")
    shutil.copyfile(DATA / "clips" / "bgbu5a.align", tmp_path / "quiet.align")
    write_wav(tmp_path / "quiet.wav", Audio(np.zeros(16000 * 3), 16000))
    out = tmp_path / "out.json"
    assert bench_main([str(tmp_path), "--json", str(out)]) == 0
    results = json.loads(out.read_text(encoding="utf-8"))
    assert [clip["clip"] for clip in results["clips"]] == list(CLIPS_ALIGNED)
    [refused] = results["refused"]
    assert refused["clip"] == "quiet" and refused["code"] == "not_speech"
    errors = []
    for clip in results["clips"]:
        rows = [line.split() for line in (clips / f"{clip['clip']}.align").read_text().split("\n")]
        truth = [(w, int(a) / GRID_UNITS_PER_S) for a, _, w in filter(None, rows) if w != "sil"]
        truth = [(w, t) for w, t in truth if w != "sp"]
        assert [row["word"] for row in clip["words"]] == [word for word, _ in truth]
        errors += [1000 * abs(row["aligned_s"][0] - t) for row, (_, t) in zip(clip["words"], truth)]
    assert max(errors) <= CLIPS_MAX_ONSET_MS and np.median(errors) <= CLIPS_MEDIAN_ONSET_MS
    assert results["all"]["words"] == 18 and results["all"]["refused"] == 1
    positions = results["all"]["onset_by_position"]
    assert len(positions) == 6
    first = [abs(clip["onset_errors_ms"][0]) for clip in results["clips"]]
    assert positions[0]["max_ms"] == pytest.approx(max(first), abs=0.06)
