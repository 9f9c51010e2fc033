"""Live Link Face exports load as the app wrote them.

Always: two takes this test writes in the app's exact format (``tests/livelink_takes.py``).
Also, when ``LIPSTREAM_LIVELINK_DIR`` points at them, the two real exports of the app
(``.ci/run`` sets it to ``../shared/data/livelink-face`` when that directory exists).
"""

from __future__ import annotations

import csv
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from lipstream.corpus import load_corpus, read_livelink_csv
from lipstream.corpus.livelink import ARKIT_BLENDSHAPES, ROTATIONS
from lipstream.errors import CorpusError
from tests.helpers import LIVELINK_DIR_VARIABLE, real_livelink_takes
from tests.livelink_takes import APP_COLUMNS, TAKES, SyntheticTake, take_values, write_take

REAL_TAKES = real_livelink_takes()
SOURCES: list[SyntheticTake | Path] = [*TAKES, *REAL_TAKES]
DAY_S = 86400


def source_id(source: SyntheticTake | Path) -> str:
    return (
        f"synthetic-{source.stem}" if isinstance(source, SyntheticTake) else f"real-{source.stem}"
    )


@pytest.fixture(scope="module")
def written(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    directory = tmp_path_factory.mktemp("livelink")
    return {take.stem: write_take(directory, take) for take in TAKES}


@pytest.fixture(params=SOURCES, ids=source_id)
def source(request: pytest.FixtureRequest) -> SyntheticTake | Path:
    chosen: SyntheticTake | Path = request.param
    return chosen


@pytest.fixture
def take(source: SyntheticTake | Path, written: dict[str, Path]) -> Path:
    """The CSV file of ``source``: written by this test, or a real export."""
    return written[source.stem] if isinstance(source, SyntheticTake) else source


def raw_rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))


def timecode_seconds(code: str) -> float:
    hours, minutes, seconds, frames = code.split(":")
    return int(hours) * 3600 + int(minutes) * 60 + int(seconds) + float(frames) / 60


def span_seconds(rows: list[dict[str, str]]) -> float:
    """First to last timecode, across midnight if the take runs past it."""
    return (timecode_seconds(rows[-1]["Timecode"]) - timecode_seconds(rows[0]["Timecode"])) % DAY_S


def test_every_take_source_is_collected() -> None:
    assert len(TAKES) == 2 and len(SOURCES) == len(TAKES) + len(REAL_TAKES)
    if os.environ.get(LIVELINK_DIR_VARIABLE, "").strip():
        assert len(REAL_TAKES) == 2, f"${LIVELINK_DIR_VARIABLE} holds no pair of exports"


def test_written_takes_have_the_apps_layout(written: dict[str, Path]) -> None:
    for take in TAKES:
        lines = written[take.stem].read_text(encoding="utf-8").split("\n")
        assert lines[0] == ",".join(APP_COLUMNS) and len(APP_COLUMNS) == 63
        assert lines[-1] == "" and len(lines) == take.rows + 2
        assert lines[1].split(",")[1] == "61"
        assert all(len(line.split(",")) == 63 for line in lines[1:-1])
    codes = [line.split(",")[0] for line in written[TAKES[1].stem].read_text().splitlines()]
    assert codes[1] == "23:59:55:30.000" and codes[-1] == "00:00:06:30.054"
    before = max(k for k, code in enumerate(codes) if code.startswith("23:59:59:"))
    assert codes[before + 1].startswith("00:00:00:")


@pytest.mark.parametrize(
    ("clock_s", "expected"),
    [(0.0, "00:00:00:00.000"), (69395.58788, "19:16:35:35.273"), (86399.999, "23:59:59:59.940")],
)
def test_timecodes_are_written_in_the_apps_form(clock_s: float, expected: str) -> None:
    from tests.livelink_takes import timecode

    assert timecode(clock_s) == expected


def test_reader_keeps_every_row_and_column(source: SyntheticTake | Path, take: Path) -> None:
    rows = raw_rows(take)
    times, frames, channels = read_livelink_csv(take)
    assert len(ARKIT_BLENDSHAPES) == 52
    assert channels == ARKIT_BLENDSHAPES + ROTATIONS  # the app's column order
    assert {"jawOpen", "mouthClose", "headYaw", "tongueOut", "leftEyeYaw"} <= set(channels)
    assert frames.shape == (len(rows), 61)
    assert times[0] == 0.0
    assert frames[0, channels.index("jawOpen")] == np.float32(rows[0]["JawOpen"])
    assert frames[-1, channels.index("headRoll")] == np.float32(rows[-1]["HeadRoll"])
    assert times[-1] == pytest.approx(span_seconds(rows), abs=1e-9)
    if isinstance(source, SyntheticTake):
        np.testing.assert_array_equal(frames, take_values(source).astype(np.float32))
        assert times[-1] == pytest.approx(source.span_s, abs=1e-3 / 60)
        assert frames.min() < 0.0 and frames[:, :52].min() == 0.0
    else:
        assert 29.0 < times[-1] < 33.0  # the real takes are about 30 s long


def test_rows_step_one_sixtieth_across_frame_wraps(take: Path) -> None:
    rows = raw_rows(take)
    times = read_livelink_csv(take).times
    steps = np.diff(times)
    assert np.all(np.abs(steps - 1 / 60) < 1e-4)
    frame_fields = [float(row["Timecode"].split(":")[3]) for row in rows]
    wraps = [k for k in range(1, len(rows)) if frame_fields[k] < frame_fields[k - 1]]
    assert len(wraps) >= int(times[-1]) >= 10  # one per second of the take
    for k in wraps:
        assert steps[k - 1] == pytest.approx(1 / 60, abs=1e-4)


def test_take_loads_as_a_corpus_at_60_fps(take: Path, tmp_path: Path) -> None:
    rows = raw_rows(take)
    span = span_seconds(rows)
    shutil.copy(take, tmp_path / "take.csv")
    (tmp_path / "take.lab").write_text(f"0.0 {span - 0.5:.3f} sil\n")
    corpus = load_corpus(tmp_path)
    assert corpus.fps == 60.0
    assert {"jawOpen", "mouthClose", "headYaw"} <= set(corpus.channels)
    utterance = corpus.utterances[0]
    assert utterance.frames[0, corpus.channels.index("jawOpen")] == np.float32(rows[0]["JawOpen"])
    assert utterance.n_frames == int(span * 60) + 1
    assert utterance.duration == pytest.approx(span, abs=1 / 60)
    assert "BlendshapeCount" not in corpus.channels and "blendshapeCount" not in corpus.channels


def test_midnight_wrap_and_bad_timecode(tmp_path: Path) -> None:
    header = "Timecode,BlendshapeCount,JawOpen,HeadYaw\n"
    path = tmp_path / "late.csv"
    path.write_text(
        header + "23:59:59:58.500,2,0.1,0.0\n23:59:59:59.500,2,0.2,0.0\n00:00:00:00.500,2,0.3,0.0\n"
    )
    times, frames, channels = read_livelink_csv(path)
    np.testing.assert_allclose(times, [0.0, 1 / 60, 2 / 60], atol=1e-9)
    np.testing.assert_array_equal(frames[:, 0], np.array([0.1, 0.2, 0.3], dtype=np.float32))
    assert channels == ("jawOpen", "headYaw")
    path.write_text(header + "10:00:00:01.000,2,0.1,0.0\n10:00:00:61.000,2,0.2,0.0\n")
    with pytest.raises(CorpusError, match=r"late\.csv:line 3.*out of range"):
        read_livelink_csv(path)
    path.write_text(header + "10:00:00:01.000,2,0.1,0.0\n10:00:00,2,0.2,0.0\n")
    with pytest.raises(CorpusError, match=r"late\.csv:line 3.*'Timecode'"):
        read_livelink_csv(path)
    path.write_text(header.replace("JawOpen", "JawWobble") + "10:00:00:01.000,2,0.1,0.0\n")
    with pytest.raises(CorpusError, match=r"late\.csv:line 1.*'JawWobble'"):
        read_livelink_csv(path)
