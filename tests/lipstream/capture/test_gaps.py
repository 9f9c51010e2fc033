"""Tracking drop-outs: short gaps bridged by linear interpolation in time, long ones and
faceless or crowded videos refused with coded errors."""

from __future__ import annotations

import numpy as np
import pytest

from lipstream.capture.gaps import bridge_gaps, check_faces
from lipstream.capture.track import Track
from lipstream.errors import LipstreamError

FPS = 25.0


def track(missing: list[int], n: int = 50, faces: dict[int, int] | None = None) -> Track:
    times = np.arange(n) / FPS
    # Every coordinate of frame i is a known linear function of its time.
    landmarks = np.broadcast_to((3.0 * times + 1.0)[:, None, None], (n, 468, 3)).copy()
    count = np.ones(n, dtype=int)
    count[missing] = 0
    landmarks[missing] = np.nan
    for index, value in (faces or {}).items():
        count[index] = value
    return Track(times, landmarks, count)


def test_a_gap_of_two_frames_at_25_fps_is_bridged_on_the_line() -> None:
    bridged = bridge_gaps(track([20, 21]), "clip.mp4")  # lost for 80 ms
    expected = 3.0 * np.arange(50) / FPS + 1.0
    np.testing.assert_allclose(bridged.landmarks[:, 100, 1], expected)
    assert not np.isnan(bridged.landmarks).any()


def test_a_gap_at_the_start_holds_the_first_tracked_frame() -> None:
    bridged = bridge_gaps(track([0, 1]), "clip.mp4")
    assert bridged.landmarks[0, 0, 0] == pytest.approx(3.0 * 2 / FPS + 1.0)


def test_a_gap_of_three_frames_at_25_fps_is_refused_naming_it() -> None:
    with pytest.raises(LipstreamError) as raised:
        bridge_gaps(track([20, 21, 22]), "clip.mp4")  # lost for 120 ms
    error = raised.value
    assert error.code == "tracking_gap" and error.where == "clip.mp4"
    assert "0.80 s to 0.92 s" in error.message


def test_a_gap_running_off_the_end_counts_to_one_frame_past_it() -> None:
    bridge_gaps(track([48, 49]), "clip.mp4")
    with pytest.raises(LipstreamError, match="tracking_gap"):
        bridge_gaps(track([47, 48, 49]), "clip.mp4")


def test_no_face_gives_the_share_of_frames_found() -> None:
    with pytest.raises(LipstreamError) as raised:
        check_faces(track(list(range(30))), "clip.mp4")  # found in 20 of 50
    assert raised.value.code == "no_face" and "40% of 50 frames" in raised.value.message


def test_a_second_face_is_refused_naming_when() -> None:
    with pytest.raises(LipstreamError) as raised:
        check_faces(track([], faces={10: 2, 11: 2}), "clip.mp4")
    assert raised.value.code == "several_faces"
    assert "2 of 50 frames" in raised.value.message and "0.40 s" in raised.value.message
