"""The motion track: the chosen fragments laid on the request's timeline, blended.

Sketch: position j of the query shows anime A_j over the target span
[a_j, b_j); the warp maps target time to A_j's recording time, and the
fragment's value is the recording's PCA curve there. Each join adds the
corrections planned by ``blending`` (pair example or extension), so the
track is a continuous function of time, evaluated wherever the synthesizer
needs samples. Evaluating position j needs the joins on both of its sides,
except with forward joins (causal rungs), which correct only the span after
them; those rungs also evaluate left-continuously (a span's end belongs to
it), so a decided span is evaluated up to its end.
Placements and joins are also kept as flat, growing arrays, so one compiled
call (``evaluate_track``) samples any stretch of the track: it runs on every
streamed message, where per-fragment numpy calls cost more than the samples.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypeAlias

import numpy as np
from numba import njit

from ..growable import Growable
from .animes import AnimeTable, sample_into
from .blending import Join, JoinKind
from .warp import Warp

_NO_CORRECTION, _PAIR, _EXTEND, _FORWARD = 0, 1, 2, 3
_KIND_CODES = {JoinKind.PAIR: _PAIR, JoinKind.EXTEND: _EXTEND, JoinKind.FORWARD: _FORWARD}
FORWARD_BLEND_SHARE = 0.5
"""A forward join blends the previous recording out over this share of the next span, so a
short span (a closure) still reaches its own fragment's pose."""
TrackArrays: TypeAlias = tuple[
    np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
    np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, float,
]  # fmt: skip


@dataclass(frozen=True)
class Placement:
    """Anime ``anime`` shown over the target span [start, end) s through ``warp``."""

    start: float
    end: float
    anime: int
    warp: Warp


class MotionTrack:
    """Placements in timeline order and the joins between neighbours."""

    def __init__(self, animes: AnimeTable) -> None:
        self.animes = animes
        self.placements: list[Placement] = []
        self.joins: list[Join] = []
        self._starts = Growable(np.float64)
        self._ends = Growable(np.float64)
        self._animes = Growable(np.int64)
        self._knot_offsets = Growable(np.int64)
        self._knot_offsets.append(0)
        self._knot_targets = Growable(np.float64)
        self._knot_sources = Growable(np.float64)
        self._join_kinds = Growable(np.int64)
        self._join_examples = (Growable(np.int64), Growable(np.int64))

    def __len__(self) -> int:
        return len(self.placements)

    def append(self, placement: Placement, join: Join | None) -> None:
        """Add the next placement; ``join`` from the previous one (None for the first)."""
        if self.placements:
            if join is None:
                raise ValueError("a placement after the first needs its join")
            self.joins.append(join)
            self._join_kinds.append(_KIND_CODES.get(join.kind, _NO_CORRECTION))
            self._join_examples[0].append(join.left_example)
            self._join_examples[1].append(join.right_example)
        self.placements.append(placement)
        self._starts.append(placement.start)
        self._ends.append(placement.end)
        self._animes.append(placement.anime)
        self._knot_targets.extend(placement.warp.target)
        self._knot_sources.extend(placement.warp.source)
        self._knot_offsets.append(self._knot_targets.count)

    def evaluate(self, times: np.ndarray, left_continuous: bool = False) -> np.ndarray:
        """Track values (n, n_pc) at ascending ``times``; a time belongs to the last
        placement starting at or before it (``left_continuous``: strictly before it)."""
        return evaluate_track(np.asarray(times, dtype=np.float64), *self.arrays(), left_continuous)

    def arrays(self) -> TrackArrays:
        """The track as the flat arrays that ``evaluate_track`` (and kernels calling it) read,
        in its argument order after ``times``."""
        animes, motion = self.animes, self.animes.motion
        return (
            self._starts.view(),
            self._ends.view(),
            self._animes.view(),
            self._knot_offsets.view(),
            self._knot_targets.view(),
            self._knot_sources.view(),
            self._join_kinds.view(),
            self._join_examples[0].view(),
            self._join_examples[1].view(),
            animes.start,
            animes.end,
            animes.utterance,
            motion.values,
            motion.offsets,
            float(motion.rate),
        )


@njit(cache=True)
def evaluate_track(
    times: np.ndarray,
    starts: np.ndarray,
    ends: np.ndarray,
    animes: np.ndarray,
    knot_offsets: np.ndarray,
    knot_targets: np.ndarray,
    knot_sources: np.ndarray,
    join_kinds: np.ndarray,
    left_examples: np.ndarray,
    right_examples: np.ndarray,
    anime_start: np.ndarray,
    anime_end: np.ndarray,
    utterance: np.ndarray,
    values: np.ndarray,
    offsets: np.ndarray,
    rate: float,
    left_continuous: bool,
) -> np.ndarray:
    """Each time's fragment value plus the corrections of the joins on either side:
    out = base + w_left (left - base) + w_right (right - base), w clipped to [0, 1]."""
    out = np.empty((len(times), values.shape[1]))
    base = np.empty(values.shape[1])
    other = np.empty(values.shape[1])
    for row in range(len(times)):
        time = times[row]
        if left_continuous:
            index = max(np.searchsorted(starts, time, side="left") - 1, 0)
        else:
            index = max(np.searchsorted(starts, time, side="right") - 1, 0)
        low, high = knot_offsets[index], knot_offsets[index + 1]
        recording = np.interp(time, knot_targets[low:high], knot_sources[low:high])
        sample_into(base, values, offsets, utterance[animes[index]], recording, rate, True)
        out[row] = base
        for side in range(2):
            join = index - 1 if side == 0 else index
            if join < 0 or join >= len(join_kinds) or join_kinds[join] == _NO_CORRECTION:
                continue
            if join_kinds[join] == _FORWARD and side == 1:
                continue
            weight, anime, recording = _correction(
                side,
                join_kinds[join],
                time,
                index,
                starts,
                ends,
                animes,
                right_examples[join] if side == 0 else left_examples[join],
                anime_start,
                anime_end,
            )
            weight = min(max(weight, 0.0), 1.0)
            if weight > 0.0:
                sample_into(other, values, offsets, utterance[anime], recording, rate, True)
                for column in range(values.shape[1]):
                    out[row, column] += weight * (other[column] - base[column])
    return out


@njit(cache=True)
def _correction(
    side: int,
    kind: int,
    time: float,
    index: int,
    starts: np.ndarray,
    ends: np.ndarray,
    animes: np.ndarray,
    example: int,
    anime_start: np.ndarray,
    anime_end: np.ndarray,
) -> tuple[float, int, float]:
    """(weight, anime, recording time) of the correction from the left (``side`` 0) or
    right (1) join of placement ``index``: a pair example stretched onto the span, or the
    neighbour's recording extended across it."""
    start, end = starts[index], ends[index]
    if kind == _PAIR:
        relative = (time - start) / (end - start)
        recording = anime_start[example] + relative * (anime_end[example] - anime_start[example])
        return (1.0 - relative if side == 0 else relative), example, recording
    if kind == _FORWARD:
        before = animes[index - 1]
        return (
            1.0 - (time - start) / (FORWARD_BLEND_SHARE * (end - start)),
            before,
            anime_end[before] + time - ends[index - 1],
        )
    if side == 0:
        before = animes[index - 1]
        weight = 1.0 - (time - starts[index - 1]) / (end - starts[index - 1])
        return weight, before, anime_end[before] + time - ends[index - 1]
    after = animes[index + 1]
    weight = (time - start) / (ends[index + 1] - start)
    return weight, after, anime_start[after] - (starts[index + 1] - time)
