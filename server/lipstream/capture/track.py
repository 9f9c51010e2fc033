"""Face tracking with MediaPipe FaceMesh (mediapipe 0.10.14, its models inside the wheel).

Sketch: FaceMesh runs in tracking mode (its face detector only when it has lost the face)
and looks for up to two faces, so a second face is seen rather than silently followed.
Each frame gives 468 landmarks in pixels: x and y in the picture, z (depth, relative to
the face's centre) on the x scale, as FaceMesh defines it. A frame without a face is NaN.
Tracking counts the frames that held more than one face, for the ``several_faces`` check.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from .decode import VideoFrame

N_LANDMARKS = 468
MAX_FACES = 2
MIN_DETECTION_CONFIDENCE = 0.5
MIN_TRACKING_CONFIDENCE = 0.5


@dataclass(frozen=True)
class Track:
    """``times`` (n,) s; ``landmarks`` (n, 468, 3) pixels, NaN where no face was found;
    ``faces`` (n,) the number of faces FaceMesh found in each frame."""

    times: np.ndarray
    landmarks: np.ndarray
    faces: np.ndarray

    @property
    def found(self) -> np.ndarray:
        """(n,) bool: the frames with a face."""
        return np.asarray(self.faces > 0)


def face_mesh() -> Any:
    """A FaceMesh in tracking mode; ``missing_dependency`` when mediapipe is not installed."""
    from .dependencies import require

    solutions = require("mediapipe.python.solutions.face_mesh")
    return solutions.FaceMesh(
        static_image_mode=False,
        max_num_faces=MAX_FACES,
        refine_landmarks=False,
        min_detection_confidence=MIN_DETECTION_CONFIDENCE,
        min_tracking_confidence=MIN_TRACKING_CONFIDENCE,
    )


def track_faces(frames: Iterable[VideoFrame]) -> Track:
    """Landmarks of the face in every frame (the first FaceMesh reports when it finds two)."""
    times: list[float] = []
    points: list[np.ndarray] = []
    faces: list[int] = []
    missing = np.full((N_LANDMARKS, 3), np.nan)
    with warnings.catch_warnings(), face_mesh() as mesh:
        # mediapipe 0.10.14 calls a protobuf 4 API that warns on every frame
        warnings.filterwarnings("ignore", "SymbolDatabase.GetPrototype", UserWarning)
        for frame in frames:
            height, width = frame.rgb.shape[:2]
            result = mesh.process(frame.rgb)
            found = result.multi_face_landmarks or []
            times.append(frame.time)
            faces.append(len(found))
            if found:
                landmarks = found[0].landmark
                points.append(
                    np.array(
                        [(p.x * width, p.y * height, p.z * width) for p in landmarks],
                        dtype=np.float64,
                    )
                )
            else:
                points.append(missing)
    if not times:
        return Track(np.zeros(0), np.zeros((0, N_LANDMARKS, 3)), np.zeros(0, dtype=int))
    return Track(np.array(times), np.stack(points), np.array(faces))
