"""Live Link Face CSV export: the app's header, its timecodes, and a round trip through our
reader."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lipstream.corpus.livelink import read_livelink_csv
from lipstream.corpus.loader import read_frames
from lipstream.engines.base import SynthesisResult
from lipstream.errors import InvalidRequestError
from lipstream.exports.livelink import livelink_csv, timecode
from lipstream.exports.writer import write_export
from tests.helpers import real_livelink_takes
from tests.livelink_takes import APP_HEADER


@pytest.mark.parametrize(
    ("seconds", "expected"),
    [
        (0.0, "00:00:00:00.000"),
        (1 / 30, "00:00:00:02.000"),
        (0.01, "00:00:00:00.600"),
        (1.5, "00:00:01:30.000"),
        (3661.25, "01:01:01:15.000"),
        (59.9999999, "00:01:00:00.000"),  # rounds up across the minute
    ],
)
def test_timecode_counts_60_fps_frames_to_the_thousandth(seconds: float, expected: str) -> None:
    assert timecode(seconds) == expected


def test_header_is_the_iphone_apps_header() -> None:
    text = livelink_csv(np.zeros((1, 1), dtype=np.float32), ("jawOpen",), 60.0)
    assert text.splitlines()[0] == APP_HEADER
    for export in real_livelink_takes():  # the real exports, when LIPSTREAM_LIVELINK_DIR is set
        assert text.splitlines()[0] == export.read_text().splitlines()[0]


def test_round_trip_through_the_corpus_reader(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    channels = ("jawOpen", "MouthClose", "headYaw")  # ARKit and livelink spellings
    frames = rng.uniform(-0.5, 1.0, (45, 3)).astype(np.float32)
    path = tmp_path / "take.csv"
    result = SynthesisResult(frames, channels, 30.0)
    assert write_export(path, result, "livelink") == "livelink"

    table = read_livelink_csv(path)
    np.testing.assert_allclose(table.times, np.arange(45) / 30.0, atol=2e-5)
    assert len(table.channels) == 61
    for column, name in enumerate(("jawOpen", "mouthClose", "headYaw")):
        np.testing.assert_allclose(
            table.frames[:, table.channels.index(name)], frames[:, column], atol=1e-9
        )
    others = [
        i
        for i, name in enumerate(table.channels)
        if name not in ("jawOpen", "mouthClose", "headYaw")
    ]
    assert not table.frames[:, others].any()
    # The corpus loader recognises it as a Live Link export by its header.
    assert read_frames(path).channels == table.channels
    second = path.read_text().splitlines()[2]
    assert second.startswith("00:00:00:02.000,61,")


def test_a_channel_live_link_has_no_column_for_is_refused() -> None:
    with pytest.raises(InvalidRequestError, match="'viseme_aa'"):
        livelink_csv(np.zeros((2, 1), dtype=np.float32), ("viseme_aa",), 60.0)
