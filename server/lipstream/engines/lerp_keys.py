"""``viseme-lerp``'s interpolation, compiled: keys at span centres, channels linear between.

Sketch: a key sits at the centre of every span, with the pose row of the
span's viseme; the frame at t lies on the segment between the last key at or
before t and the next one, held flat before the first key and after the last
(``np.interp`` per channel). ``lerp_frames`` (numba) writes a run of frames
directly: it finds the keys the run needs (the last centre at or before its
first time, up to the first centre after its last time) by stepping from a
starting key, then walks the run's times forward through that window. It
computes each value as the numpy expression it replaces did (float32 keys
widened to float64, ``left·(1 - w) + right·w``, w clipped to [0, 1], rounded
to float32: ``numerics.resample.blend_into``), so the frames are that
expression's to the bit.

``KeyedSpans`` is a request's span list that also keeps each span's centre and
phoneme in growing arrays (brought up to date when the keys are read, so only
new spans cost anything) and the first key of its latest run: a streaming
request's runs only move forward, so finding the window costs a step or two,
however long the request.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numba import njit

from ..numerics.resample import blend_into
from ..phonemes import PHONEME_INDEX
from ..timeline import PhonemeSpan
from .growable import Growable


class KeyedSpans(list[PhonemeSpan]):
    """Spans, with ``centres`` (s) and ``phonemes`` (indices into ``PHONEMES``) of the first
    ``centres.count`` of them, and ``first_key``: the first key the latest run needed."""

    def __init__(self, spans: Sequence[PhonemeSpan] = ()) -> None:
        super().__init__(spans)
        self.centres = Growable(np.float64)
        self.phonemes = Growable(np.int64)
        self.first_key = 0

    def keys(self) -> tuple[np.ndarray, np.ndarray]:
        """Every span's centre and phoneme index, (n,) each."""
        for span in self[self.centres.count :]:
            self.centres.append(span.centre)
            self.phonemes.append(PHONEME_INDEX[span.phoneme])
        return self.centres.view(), self.phonemes.view()


@njit(cache=True)
def lerp_frames(
    centres: np.ndarray,
    phonemes: np.ndarray,
    pose_rows: np.ndarray,
    poses: np.ndarray,
    times: np.ndarray,
    start_key: int,
) -> tuple[np.ndarray, int]:
    """Frames float32 (len(times), channels) at ascending ``times``: ``poses`` (float32) row
    ``pose_rows[phonemes[k]]`` at ``centres[k]``, interpolated linearly, held flat outside
    (at least one key). The window search steps from ``start_key``; returned with the
    frames is the window's first key (the last centre at or before times[0], else 0)."""
    n = len(centres)
    out = np.empty((len(times), poses.shape[1]), dtype=np.float32)
    key = min(max(start_key, 0), n - 1)
    if len(times) == 0:
        return out, key
    while key > 0 and centres[key] > times[0]:
        key -= 1
    while key + 1 < n and centres[key + 1] <= times[0]:
        key += 1
    last = key
    while last < n and centres[last] <= times[-1]:
        last += 1
    last = min(last, n - 1)
    if last == key:
        out[:] = poses[pose_rows[phonemes[key]]]
        return out, key
    left = key
    for i in range(len(times)):
        t = times[i]
        while left + 1 < last and centres[left + 1] <= t:
            left += 1
        while left > key and centres[left] > t:
            left -= 1
        weight = (t - centres[left]) / (centres[left + 1] - centres[left])
        if weight < 0.0:
            weight = 0.0
        if weight > 1.0:
            weight = 1.0
        low, high = pose_rows[phonemes[left]], pose_rows[phonemes[left + 1]]
        blend_into(out[i], poses, low, high, weight)
    return out, key
