"""Landmarks in the face's frame to ARKit-named channels in [0, 1].

Sketch: each channel is one geometric measure on the pose-free landmarks (``pose``), in
units of the outer eye-corner distance, taken relative to the speaker's rest (a measure
is 0 at rest), then divided by the speaker's own 99th percentile of that measure and
clipped to [0, 1]. The rest is the per-landmark median of the quietest frames: among the
frames the aligner put in silence (all frames if there are too few), the fifth whose
jaw drop plus inner-lip gap is smallest. Landmark numbers are MediaPipe FaceMesh's;
"left" is the speaker's left (+x), y points down, -z out of the face.

| channel | measure (positive direction) |
|---|---|
| jawOpen | chin (152) moving down |
| mouthClose | chin drop minus inner-lip gap growth: lips kept together as the jaw opens |
| mouthPucker | rounding (corners 61-291 closer, lips 0/17 forward) while the lips are closed |
| mouthFunnel | the same rounding while the lips are apart |
| mouthStretchLeft/Right | mouth corner 291 / 61 moving outward |
| mouthSmileLeft/Right | mouth corner 291 / 61 moving up |
| mouthRollUpper | upper lip's red (0 to 13) thinning, against the clip's median |
| mouthRollLower | lower lip's red (14 to 17) thinning, against the clip's median |
| mouthLowerDownLeft/Right | lower lip at 314 / 84 moving down |
| mouthUpperUpLeft/Right | upper lip at 267 / 37 moving up |

The rolls are measured against the clip's median lip height rather than the rest, since
the rest (lips closed) already presses the lips thin. Rounding (corners 61-291 closer plus
lips 0/17 forward) splits between pucker and funnel by the lips' opening share (the
inner-lip gap growth over the speaker's 99th percentile of it): pucker is rounding times
(1 - opening), funnel rounding times opening.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..tables import names

CHIN = 152
UPPER_LIP_TOP, UPPER_LIP_INNER, LOWER_LIP_INNER, LOWER_LIP_BOTTOM = 0, 13, 14, 17
RIGHT_CORNER, LEFT_CORNER = 61, 291
RIGHT_UPPER_LIP, LEFT_UPPER_LIP = 37, 267
RIGHT_LOWER_LIP, LEFT_LOWER_LIP = 84, 314
X, Y, Z = 0, 1, 2

CHANNELS: tuple[str, ...] = names("""
    jawOpen mouthClose mouthFunnel mouthPucker
    mouthStretchLeft mouthStretchRight mouthSmileLeft mouthSmileRight
    mouthRollLower mouthRollUpper mouthLowerDownLeft mouthLowerDownRight
    mouthUpperUpLeft mouthUpperUpRight
""")
RANGE_PERCENTILE = 99.0
REST_SHARE = 0.2
MIN_REST_FRAMES = 3
# A speaker whose 99th percentile stays under this (face-scale units: 1% of the eye-corner
# distance, about FaceMesh's frame-to-frame jitter) never made the move: the channel
# stays 0 rather than amplifying tracking noise.
MIN_RANGE = 0.01


def rest_pose(face: np.ndarray, quiet: np.ndarray) -> np.ndarray:
    """The rest landmarks (468, 3) of ``face`` (n, 468, 3); ``quiet`` (n,) marks the
    frames in silence."""
    pool = np.flatnonzero(quiet) if quiet.sum() >= MIN_REST_FRAMES else np.arange(len(face))
    closure = face[pool, CHIN, Y] + face[pool, LOWER_LIP_INNER, Y] - face[pool, UPPER_LIP_INNER, Y]
    keep = max(1, int(np.ceil(REST_SHARE * len(pool))))
    quietest = pool[np.argsort(closure, kind="stable")[:keep]]
    rest: np.ndarray = np.median(face[quietest], axis=0)
    return rest


def raw_measures(face: np.ndarray, rest: np.ndarray) -> dict[str, np.ndarray]:
    """Each channel's measure (n,) relative to ``rest``, before rounding is split and
    before the range map; ``"rounding"`` and ``"lip_gap"`` are the two shared parts."""

    def moved(index: int, axis: int) -> np.ndarray:
        delta: np.ndarray = face[:, index, axis] - rest[index, axis]
        return delta

    def gap(points: np.ndarray, upper: int, lower: int) -> np.ndarray:
        distance: np.ndarray = points[..., lower, Y] - points[..., upper, Y]
        return distance

    def thinning(upper: int, lower: int) -> np.ndarray:
        # Against the clip's median: the rest (lips closed) already presses the lips.
        height = gap(face, upper, lower)
        result: np.ndarray = np.median(height) - height
        return result

    jaw = moved(CHIN, Y)
    lip_gap = gap(face, UPPER_LIP_INNER, LOWER_LIP_INNER) - gap(
        rest, UPPER_LIP_INNER, LOWER_LIP_INNER
    )
    width = np.linalg.norm(face[:, LEFT_CORNER] - face[:, RIGHT_CORNER], axis=1)
    rest_width = float(np.linalg.norm(rest[LEFT_CORNER] - rest[RIGHT_CORNER]))
    forward = -0.5 * (moved(UPPER_LIP_TOP, Z) + moved(LOWER_LIP_BOTTOM, Z))
    return {
        "jawOpen": jaw,
        "mouthClose": jaw - lip_gap,
        "rounding": (rest_width - width) + forward,
        "lip_gap": lip_gap,
        "mouthStretchLeft": moved(LEFT_CORNER, X),
        "mouthStretchRight": -moved(RIGHT_CORNER, X),
        "mouthSmileLeft": -moved(LEFT_CORNER, Y),
        "mouthSmileRight": -moved(RIGHT_CORNER, Y),
        "mouthRollUpper": thinning(UPPER_LIP_TOP, UPPER_LIP_INNER),
        "mouthRollLower": thinning(LOWER_LIP_INNER, LOWER_LIP_BOTTOM),
        "mouthLowerDownLeft": moved(LEFT_LOWER_LIP, Y),
        "mouthLowerDownRight": moved(RIGHT_LOWER_LIP, Y),
        "mouthUpperUpLeft": -moved(LEFT_UPPER_LIP, Y),
        "mouthUpperUpRight": -moved(RIGHT_UPPER_LIP, Y),
    }


def speaker_ranges(measures: Sequence[dict[str, np.ndarray]]) -> dict[str, float]:
    """Each measure's 99th percentile over all of one speaker's frames (0 when below
    ``MIN_RANGE``: the speaker never made that move)."""
    ranges = {}
    for name in measures[0]:
        values = np.concatenate([measure[name] for measure in measures])
        top = float(np.percentile(values, RANGE_PERCENTILE))
        ranges[name] = top if top >= MIN_RANGE else 0.0
    return ranges


def to_channels(measures: dict[str, np.ndarray], ranges: dict[str, float]) -> np.ndarray:
    """(n, len(CHANNELS)) float32 in [0, 1], columns in ``CHANNELS`` order."""

    def scaled(values: np.ndarray, name: str) -> np.ndarray:
        top = ranges[name]
        if top <= 0.0:
            return np.zeros_like(values)
        result: np.ndarray = np.clip(values / top, 0.0, 1.0)
        return result

    opening = scaled(measures["lip_gap"], "lip_gap")
    rounding = scaled(measures["rounding"], "rounding")
    columns = {
        name: scaled(measures[name], name)
        for name in CHANNELS
        if name not in ("mouthPucker", "mouthFunnel")
    }
    columns["mouthPucker"] = rounding * (1.0 - opening)
    columns["mouthFunnel"] = rounding * opening
    return np.stack([columns[name] for name in CHANNELS], axis=1).astype(np.float32)
