"""The motion track: the chosen fragments laid on the request's timeline, blended.

Sketch: position j of the query shows anime A_j over the target span
[a_j, b_j); the warp maps target time to A_j's recording time, and the
fragment's value is the recording's PCA curve there. Each join adds the
corrections planned by ``blending`` (pair example or extension), so the
track is a continuous function of time, evaluated wherever the synthesizer
needs samples. Evaluating position j needs the joins on both of its sides.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .animes import AnimeTable
from .blending import Join, JoinKind
from .warp import Warp


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
        self._starts: list[float] = []

    def __len__(self) -> int:
        return len(self.placements)

    def append(self, placement: Placement, join: Join | None) -> None:
        """Add the next placement; ``join`` from the previous one (None for the first)."""
        if self.placements:
            if join is None:
                raise ValueError("a placement after the first needs its join")
            self.joins.append(join)
        self.placements.append(placement)
        self._starts.append(placement.start)

    def _stretched(self, anime: int, place: Placement, times: np.ndarray) -> np.ndarray:
        """Recording times of ``anime`` linearly time-warped onto ``place``'s span."""
        relative = (times - place.start) / (place.end - place.start)
        start, end = float(self.animes.start[anime]), float(self.animes.end[anime])
        return start + relative * (end - start)

    def _left_target(self, index: int, times: np.ndarray) -> _Target | None:
        """Blend weight, anime and recording times of the correction from the left join."""
        join = self.joins[index - 1]
        place = self.placements[index]
        if join.kind is JoinKind.PAIR:
            weight = 1.0 - (times - place.start) / (place.end - place.start)
            return weight, join.right_example, self._stretched(join.right_example, place, times)
        if join.kind is JoinKind.EXTEND:
            before = self.placements[index - 1]
            weight = 1.0 - (times - before.start) / (place.end - before.start)
            return weight, before.anime, float(self.animes.end[before.anime]) + times - before.end
        return None

    def _right_target(self, index: int, times: np.ndarray) -> _Target | None:
        """Blend weight, anime and recording times of the correction from the right join."""
        join = self.joins[index]
        place = self.placements[index]
        if join.kind is JoinKind.PAIR:
            weight = (times - place.start) / (place.end - place.start)
            return weight, join.left_example, self._stretched(join.left_example, place, times)
        if join.kind is JoinKind.EXTEND:
            after = self.placements[index + 1]
            weight = (times - place.start) / (after.end - place.start)
            recording_times = float(self.animes.start[after.anime]) - (after.start - times)
            return weight, after.anime, recording_times
        return None

    def evaluate(self, times: np.ndarray) -> np.ndarray:
        """Track values (n, n_pc) at ascending ``times``; a time belongs to the last
        placement starting at or before it."""
        owners = np.maximum(np.searchsorted(np.asarray(self._starts), times, side="right") - 1, 0)
        base = _Samples(len(times))
        corrections = [_Samples(len(times)), _Samples(len(times))]
        bounds = np.flatnonzero(np.diff(owners)) + 1
        chunk_starts = np.concatenate(([0], bounds))
        chunk_stops = np.concatenate((bounds, [len(times)]))
        for first, stop in zip(chunk_starts, chunk_stops):
            index = int(owners[first])
            chunk = slice(int(first), int(stop))
            place = self.placements[index]
            base.put(chunk, np.ones(stop - first), place.anime, place.warp(times[chunk]))
            if index > 0:
                corrections[0].put(chunk, *(self._left_target(index, times[chunk]) or ()))
            if index < len(self.joins):
                corrections[1].put(chunk, *(self._right_target(index, times[chunk]) or ()))
        values = base.sample(self.animes)
        out = values.copy()
        for correction in corrections:
            active = correction.active()
            if len(active):
                out[active] += correction.weight[active, None] * (
                    correction.sample(self.animes, active) - values[active])
        return out


_Target = tuple[np.ndarray, int, np.ndarray]


class _Samples:
    """Where to read the recordings for n track samples: weight, anime, recording time."""

    def __init__(self, count: int) -> None:
        self.weight = np.zeros(count)
        self.anime = np.zeros(count, dtype=np.int64)
        self.time = np.zeros(count)

    def put(self, chunk: slice, weight: np.ndarray | None = None, anime: int = 0,
            times: np.ndarray | None = None) -> None:
        if weight is None or times is None:
            return
        self.weight[chunk] = np.minimum(np.maximum(weight, 0.0), 1.0)
        self.anime[chunk] = anime
        self.time[chunk] = times

    def active(self) -> np.ndarray:
        return np.flatnonzero(self.weight > 0.0)

    def sample(self, animes: AnimeTable, rows: np.ndarray | None = None) -> np.ndarray:
        chosen = slice(None) if rows is None else rows
        owners = animes.utterance[self.anime[chosen]]
        return animes.motion.sample(owners, self.time[chosen], extrapolate=True)
