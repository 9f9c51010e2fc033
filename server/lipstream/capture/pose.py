"""Head pose removed: every frame's landmarks in the face's own frame, in face-scale units.

Sketch: the landmarks that do not move with speech (forehead, nose bridge, eye corners,
the face's outline at the temples: ``RIGID``) are aligned by a similarity transform
(Umeyama 1991: rotation, uniform scale, translation, least squares) to a reference, the
per-landmark median of those points after a first alignment to the first frame
(generalized Procrustes, one refinement). All 468 landmarks go through each frame's
transform. Then the reference's own axes are taken: x from the speaker's right outer eye
corner (33) to the left one (263), so +x is the speaker's left; y down the midline,
forehead (10) to nose (195), made orthogonal to x; z = x cross y, into the picture, so
-z points out of the face. The origin is the nose bridge (168) and the unit is the outer
eye-corner distance, so a measure reads the same at any distance from the camera.
"""

from __future__ import annotations

import numpy as np

RIGID: tuple[int, ...] = tuple(
    map(int, "10 151 9 8 168 6 197 195 33 133 362 263 127 356 234 454 226 446 116 345".split())
)
RIGHT_EYE_OUTER = 33
LEFT_EYE_OUTER = 263
FOREHEAD = 10
NOSE = 195
NOSE_BRIDGE = 168


def similarity(source: np.ndarray, target: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """(scale s, rotation R (3, 3), translation t (3,)) minimizing
    ``|target - (s * source @ R.T + t)|^2`` over points (n, 3) (Umeyama 1991, eqs. 40-42)."""
    mean_source, mean_target = source.mean(axis=0), target.mean(axis=0)
    centred_source, centred_target = source - mean_source, target - mean_target
    covariance = centred_target.T @ centred_source / len(source)
    u, singular, vt = np.linalg.svd(covariance)
    sign = np.eye(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        sign[2, 2] = -1.0
    rotation = u @ sign @ vt
    variance = float((centred_source**2).sum() / len(source))
    scale = float(np.trace(np.diag(singular) @ sign) / variance)
    translation = mean_target - scale * rotation @ mean_source
    return scale, rotation, translation


def align_to(landmarks: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Every frame of ``landmarks`` (n, 468, 3) moved so its rigid points best fit
    ``reference``'s (468, 3)."""
    aligned = np.empty_like(landmarks)
    target = reference[list(RIGID)]
    for index, frame in enumerate(landmarks):
        scale, rotation, translation = similarity(frame[list(RIGID)], target)
        aligned[index] = scale * frame @ rotation.T + translation
    return aligned


def face_frame(landmarks: np.ndarray) -> np.ndarray:
    """``landmarks`` (n, 468, 3) with pose removed, in the face's axes and units (above)."""
    first = align_to(landmarks, landmarks[0])
    reference = np.median(first, axis=0)
    aligned = align_to(landmarks, reference)
    x_axis = reference[LEFT_EYE_OUTER] - reference[RIGHT_EYE_OUTER]
    unit = float(np.linalg.norm(x_axis))
    x_axis = x_axis / unit
    down = reference[NOSE] - reference[FOREHEAD]
    y_axis = down - (down @ x_axis) * x_axis
    y_axis = y_axis / np.linalg.norm(y_axis)
    axes = np.stack([x_axis, y_axis, np.cross(x_axis, y_axis)])
    result: np.ndarray = (aligned - reference[NOSE_BRIDGE]) @ axes.T / unit
    return result
