"""Bridging short tracking drop-outs, refusing long ones.

Sketch: a run of frames without a face is a gap, lasting from its first frame's time to
the time of the next tracked frame (the video's own frame times; at the video's end, one
median frame step past its last frame). A gap of at most
``MAX_GAP_S`` is bridged: each landmark is interpolated linearly in time between the two
tracked frames around it (held at the first or last tracked frame at the video's ends).
A longer gap is ``tracking_gap``, naming where it is; a video whose face is missing from
more than half its frames is ``no_face``, with the share found; a video where FaceMesh
saw a second face is ``several_faces``, naming when.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..errors import LipstreamError
from ..numerics.resample import interp_columns
from .errors import NO_FACE, SEVERAL_FACES, TRACKING_GAP
from .track import Track

MAX_GAP_S = 0.1
MIN_FOUND_SHARE = 0.5


def check_faces(track: Track, where: str) -> None:
    """``no_face`` or ``several_faces`` when the track cannot be one speaker's face."""
    n = len(track.times)
    share = float(np.mean(track.found)) if n else 0.0
    if share < MIN_FOUND_SHARE:
        raise LipstreamError(
            f"no face found: a face was tracked in {share:.0%} of {n} frames "
            f"(at least {MIN_FOUND_SHARE:.0%} needed)",
            where=where,
            code=NO_FACE,
        )
    several = np.flatnonzero(track.faces > 1)
    if several.size:
        raise LipstreamError(
            f"several faces: {several.size} of {n} frames show more than one face, the first "
            f"at {track.times[several[0]]:.2f} s; capture takes one speaker",
            where=where,
            code=SEVERAL_FACES,
        )


def bridge_gaps(track: Track, where: str, max_gap_s: float = MAX_GAP_S) -> Track:
    """``track`` with every short gap filled; ``tracking_gap`` for the first long one."""
    found = track.found
    if found.all():
        return track
    tracked = np.flatnonzero(found)
    times = track.times
    step = float(np.median(np.diff(times))) if len(times) > 1 else 0.0
    for start, end in _runs(~found):
        back = times[end] if end < len(times) else times[-1] + step
        if back - times[start] > max_gap_s + 1e-9:
            raise LipstreamError(
                f"the face was lost from {times[start]:.2f} s to {back:.2f} s "
                f"({back - times[start]:.3f} s; gaps up to {max_gap_s * 1000:.0f} ms are bridged)",
                where=where,
                code=TRACKING_GAP,
            )
    landmarks = track.landmarks.reshape(len(times), -1)
    filled = interp_columns(times, times[tracked], landmarks[tracked]).astype(landmarks.dtype)
    return replace(track, landmarks=filled.reshape(track.landmarks.shape))


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, end) of every run of True in ``mask``."""
    padded = np.concatenate([[False], mask, [False]]).astype(np.int8)
    edges = np.flatnonzero(np.diff(padded))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True))
