"""The geometric mapping on synthetic landmarks with known answers: a rest face built here,
moved by known amounts (jaw drop, a corner raised, lips rounded), then put under known
rotations, scales and translations. Pose removal must give back the moves in units of the
outer eye-corner distance, whatever the pose."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from lipstream.capture.channels import (
    CHANNELS,
    raw_measures,
    rest_pose,
    speaker_ranges,
    to_channels,
)
from lipstream.capture.pose import face_frame, similarity

EYE_DISTANCE = 60.0  # pixels: the face-scale unit of the rest face below
RNG = np.random.default_rng(7)

# Speaker's right is image left (-x); y points down the face; the named points are
# MediaPipe FaceMesh's numbers, the other 450-odd are scattered over the face.
NAMED = {
    33: (-30, 0, 0),
    263: (30, 0, 0),
    10: (0, -50, 0),
    195: (0, 20, 0),
    168: (0, 0, 0),
    152: (0, 75, 0),
    0: (0, 38, -8),
    13: (0, 42, -8),
    14: (0, 43, -8),
    17: (0, 48, -8),
    61: (-16, 42, -4),
    291: (16, 42, -4),
    37: (-6, 39, -7),
    267: (6, 39, -7),
    84: (-6, 47, -7),
    314: (6, 47, -7),
}


def rest_face() -> np.ndarray:
    face = np.column_stack(
        [RNG.uniform(-40, 40, 468), RNG.uniform(-55, 80, 468), RNG.uniform(-20, 10, 468)]
    )
    for index, point in NAMED.items():
        face[index] = point
    return face


REST = rest_face()


def posed(face: np.ndarray, rotation: np.ndarray, scale: float, shift: np.ndarray) -> np.ndarray:
    return np.asarray(scale * face @ rotation.T + shift)


def random_pose(count: int) -> list[tuple[np.ndarray, float, np.ndarray]]:
    angles = RNG.uniform(-25, 25, (count, 3))
    return [
        (
            Rotation.from_euler("xyz", angle, degrees=True).as_matrix(),
            float(RNG.uniform(0.5, 3.0)),
            RNG.uniform(-300, 300, 3),
        )
        for angle in angles
    ]


def moved(**moves: tuple[int, float, float, float]) -> np.ndarray:
    face = REST.copy()
    for index, dx, dy, dz in moves.values():
        face[index] += (dx, dy, dz)
    return face


def test_similarity_recovers_a_known_rotation_scale_and_translation() -> None:
    rotation = Rotation.from_euler("xyz", (12, -30, 7), degrees=True).as_matrix()
    scale, found_rotation, shift = similarity(
        REST, posed(REST, rotation, 2.5, np.array([5, -3, 9]))
    )
    assert scale == pytest.approx(2.5, rel=1e-12)
    np.testing.assert_allclose(found_rotation, rotation, atol=1e-12)
    np.testing.assert_allclose(shift, [5, -3, 9], atol=1e-9)


def frames_under_poses(faces: list[np.ndarray]) -> np.ndarray:
    return np.stack([posed(face, *pose) for face, pose in zip(faces, random_pose(len(faces)))])


def test_a_jaw_drop_under_any_pose_reads_as_the_drop_in_eye_distances() -> None:
    drops = np.array([0, 0, 0, 3, 6, 9, 12, 15, 0, 4.5])  # pixels of the rest face
    faces = [moved(chin=(152, 0, drop, 0)) for drop in drops]
    face = face_frame(frames_under_poses(faces))
    measures = raw_measures(face, rest_pose(face, drops == 0))
    np.testing.assert_allclose(measures["jawOpen"], drops / EYE_DISTANCE, atol=1e-9)
    # The lips did not move: all of the drop is lips held together (mouthClose) ...
    np.testing.assert_allclose(measures["mouthClose"], drops / EYE_DISTANCE, atol=1e-9)
    # ... and nothing else moved.
    for name in ("mouthSmileLeft", "mouthSmileRight", "mouthStretchLeft", "mouthRollUpper"):
        np.testing.assert_allclose(measures[name], 0.0, atol=1e-9)


def test_lips_parting_with_the_jaw_are_not_mouth_close() -> None:
    drops = np.array([0, 0, 0, 6, 12])
    faces = [moved(chin=(152, 0, d, 0), inner=(14, 0, d, 0), outer=(17, 0, d, 0)) for d in drops]
    face = face_frame(frames_under_poses(faces))
    measures = raw_measures(face, rest_pose(face, drops == 0))
    np.testing.assert_allclose(measures["jawOpen"], drops / EYE_DISTANCE, atol=1e-9)
    np.testing.assert_allclose(measures["mouthClose"], 0.0, atol=1e-9)


def test_raising_the_speakers_left_corner_is_smile_left_only() -> None:
    raised = np.array([0, 0, 0, 2, 4, 8])
    faces = [moved(corner=(291, 0, -up, 0)) for up in raised]  # up is -y
    face = face_frame(frames_under_poses(faces))
    measures = raw_measures(face, rest_pose(face, raised == 0))
    np.testing.assert_allclose(measures["mouthSmileLeft"], raised / EYE_DISTANCE, atol=1e-9)
    np.testing.assert_allclose(measures["mouthSmileRight"], 0.0, atol=1e-9)


def test_pulling_the_right_corner_outward_is_stretch_right() -> None:
    pulls = np.array([0, 0, 0, 3, 6])
    faces = [moved(corner=(61, -pull, 0, 0)) for pull in pulls]  # the right corner is at -x
    face = face_frame(frames_under_poses(faces))
    measures = raw_measures(face, rest_pose(face, pulls == 0))
    np.testing.assert_allclose(measures["mouthStretchRight"], pulls / EYE_DISTANCE, atol=1e-9)
    np.testing.assert_allclose(measures["mouthStretchLeft"], 0.0, atol=1e-9)


def test_rounded_closed_lips_are_pucker_and_rounded_open_lips_funnel() -> None:
    # Frames 0-2 rest; 3 rounds the closed lips; 4 parts the lips only; 5 rounds them open.
    narrow = [0, 0, 0, 4, 0, 4]
    part = [0, 0, 0, 0, 5, 5]
    faces = [
        moved(left=(291, -w, 0, 0), right=(61, w, 0, 0), lower=(14, 0, p, 0))
        for w, p in zip(narrow, part)
    ]
    face = face_frame(frames_under_poses(faces))
    measures = raw_measures(face, rest_pose(face, np.array([1, 1, 1, 0, 0, 0], bool)))
    np.testing.assert_allclose(measures["rounding"], 2 * np.array(narrow) / EYE_DISTANCE, atol=1e-9)
    channels = to_channels(measures, speaker_ranges([measures]))
    pucker = channels[:, CHANNELS.index("mouthPucker")]
    funnel = channels[:, CHANNELS.index("mouthFunnel")]
    assert pucker[3] > 0.9 and funnel[3] == pytest.approx(0.0, abs=1e-6)
    assert funnel[5] > 0.9 and pucker[5] == pytest.approx(0.0, abs=1e-6)
    assert pucker[4] == pytest.approx(0.0, abs=1e-6) and funnel[4] == pytest.approx(0.0, abs=1e-6)


def test_channels_are_zero_at_rest_and_scale_with_the_speakers_own_range() -> None:
    drops = np.concatenate([np.zeros(5), np.linspace(1, 20, 100)])
    faces = [moved(chin=(152, 0, d, 0)) for d in drops]
    face = face_frame(frames_under_poses(faces))
    measures = raw_measures(face, rest_pose(face, drops == 0))
    jaw = to_channels(measures, speaker_ranges([measures]))[:, CHANNELS.index("jawOpen")]
    top = np.percentile(drops, 99)  # the speaker's range, from the generating drops
    np.testing.assert_allclose(jaw, np.clip(drops / top, 0, 1), atol=1e-6)
    assert jaw.min() == 0.0 and jaw.max() == 1.0
    # A move the speaker never makes stays 0 instead of blowing up tracking noise.
    smile = to_channels(measures, speaker_ranges([measures]))[:, CHANNELS.index("mouthSmileLeft")]
    assert np.all(smile == 0.0)
