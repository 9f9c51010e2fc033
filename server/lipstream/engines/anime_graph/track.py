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
Placements and joins are kept as flat arrays in buffers that double when full,
so one compiled call (``evaluate_track``) samples any stretch of the track: it
runs on every streamed message, where per-fragment numpy calls cost more than
the samples. Adding a placement writes a few numbers into those buffers
(``append_linear``: a linear warp's two knots, with no objects built; a compiled
caller may write them itself, into the buffers ``reserve`` returns, and
``commit`` them); the ``placements`` and ``joins`` lists are rebuilt from them
when asked for.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import njit

from .animes import AnimeTable, sample_into
from .blending import Join, JoinKind
from .warp import Warp

SEAMLESS_CODE, _PAIR, _EXTEND, FORWARD_CODE, CUT_CODE = 0, 1, 2, 3, 4
"""A join's kind as stored in the track (``JoinKind`` order differs); seamless and cut joins
add no correction."""
_FORWARD = FORWARD_CODE
_KIND_CODES = {
    JoinKind.SEAMLESS: SEAMLESS_CODE,
    JoinKind.PAIR: _PAIR,
    JoinKind.EXTEND: _EXTEND,
    JoinKind.FORWARD: FORWARD_CODE,
    JoinKind.CUT: CUT_CODE,
}
_KINDS = {code: kind for kind, code in _KIND_CODES.items()}
_MIN_PLACEMENTS = 16
FORWARD_BLEND_SHARE = 0.5
"""A forward join blends the previous recording out over this share of the next span, so a
short span (a closure) still reaches its own fragment's pose."""


class TrackBuffers(NamedTuple):
    """A ``MotionTrack``'s placements and joins, in buffers longer than they are: placement
    i shows anime ``animes[i]`` over [starts[i], ends[i]) s through the warp whose knots are
    knot_targets/knot_sources[knot_offsets[i] : knot_offsets[i + 1]] (target and recording
    s); join i, into placement i + 1, is ``join_kinds[i]`` (``_KIND_CODES``) with pair
    examples ``left_examples[i]``, ``right_examples[i]`` (-1: none). float64 times, int64
    ids, each array C-contiguous."""

    starts: np.ndarray
    ends: np.ndarray
    animes: np.ndarray
    knot_offsets: np.ndarray
    knot_targets: np.ndarray
    knot_sources: np.ndarray
    join_kinds: np.ndarray
    left_examples: np.ndarray
    right_examples: np.ndarray


class AnimeMotion(NamedTuple):
    """What a track is evaluated on, per anime (n,): its recording ``start`` and ``end`` (s,
    float64) and ``utterance`` (int64); the recordings' PCA curves ``values`` (n_samples,
    n_pc), utterance u owning rows offsets[u]:offsets[u + 1] (int64), at ``rate`` Hz.
    Built once per model by ``anime_motion``."""

    start: np.ndarray
    end: np.ndarray
    utterance: np.ndarray
    values: np.ndarray
    offsets: np.ndarray
    rate: float


def anime_motion(animes: AnimeTable) -> AnimeMotion:
    """``animes``' arrays as the kernels read them, with fixed dtypes, C-contiguous."""
    motion = animes.motion
    return AnimeMotion(
        np.ascontiguousarray(animes.start, dtype=np.float64),
        np.ascontiguousarray(animes.end, dtype=np.float64),
        np.ascontiguousarray(animes.utterance, dtype=np.int64),
        np.ascontiguousarray(motion.values),
        np.ascontiguousarray(motion.offsets, dtype=np.int64),
        float(motion.rate),
    )


@dataclass(frozen=True)
class Placement:
    """Anime ``anime`` shown over the target span [start, end) s through ``warp``."""

    start: float
    end: float
    anime: int
    warp: Warp


class MotionTrack:
    """Placements in timeline order and the joins between neighbours, over the animes of
    ``motion`` (``anime_motion``)."""

    def __init__(self, motion: AnimeMotion) -> None:
        self.motion = motion
        self._count = 0
        self._knots = 0
        self._starts = np.zeros(_MIN_PLACEMENTS)
        self._ends = np.zeros(_MIN_PLACEMENTS)
        self._animes = np.zeros(_MIN_PLACEMENTS, dtype=np.int64)
        self._knot_offsets = np.zeros(_MIN_PLACEMENTS + 1, dtype=np.int64)
        self._knot_targets = np.zeros(2 * _MIN_PLACEMENTS)
        self._knot_sources = np.zeros(2 * _MIN_PLACEMENTS)
        self._join_kinds = np.zeros(_MIN_PLACEMENTS, dtype=np.int64)
        self._left_examples = np.zeros(_MIN_PLACEMENTS, dtype=np.int64)
        self._right_examples = np.zeros(_MIN_PLACEMENTS, dtype=np.int64)
        self._buffers = self._gather()

    def __len__(self) -> int:
        return self._count

    @property
    def placements(self) -> list[Placement]:
        """Every placement so far, rebuilt from the track's arrays."""
        offsets = self._knot_offsets
        return [
            Placement(
                float(self._starts[index]),
                float(self._ends[index]),
                int(self._animes[index]),
                Warp(
                    self._knot_targets[offsets[index] : offsets[index + 1]].copy(),
                    self._knot_sources[offsets[index] : offsets[index + 1]].copy(),
                ),
            )
            for index in range(self._count)
        ]

    @property
    def joins(self) -> list[Join]:
        """The join into every placement after the first, rebuilt from the track's arrays."""
        return [
            Join(
                _KINDS[int(self._join_kinds[index])],
                int(self._left_examples[index]),
                int(self._right_examples[index]),
            )
            for index in range(max(self._count - 1, 0))
        ]

    def anime_at(self, index: int) -> int:
        """The anime placement ``index`` shows."""
        return int(self._animes[index])

    def append(self, placement: Placement, join: Join | None) -> None:
        """Add the next placement; ``join`` from the previous one (None for the first)."""
        warp = placement.warp
        self._add(placement.start, placement.end, placement.anime, join, len(warp.target))
        low = self._knots
        self._knot_targets[low : low + len(warp.target)] = warp.target
        self._knot_sources[low : low + len(warp.target)] = warp.source
        self._close_knots(low + len(warp.target))

    def append_linear(self, start: float, end: float, anime: int, join: Join | None) -> None:
        """``append`` of ``anime`` over [start, end) through the linear warp onto its whole
        recording (``warp.linear_warp``), without building the placement."""
        self._add(start, end, anime, join, 2)
        low = self._knots
        self._knot_targets[low] = start
        self._knot_targets[low + 1] = end
        self._knot_sources[low] = self.motion.start[anime]
        self._knot_sources[low + 1] = self.motion.end[anime]
        self._close_knots(low + 2)

    def _add(self, start: float, end: float, anime: int, join: Join | None, knots: int) -> None:
        """Room for one more placement of ``knots`` knots, its span, anime and left join."""
        index = self._count
        if index + 1 >= len(self._starts) or self._knots + knots > len(self._knot_targets):
            self._grow(index + 2, self._knots + knots)
        if index:
            if join is None:
                raise ValueError("a placement after the first needs its join")
            self._join_kinds[index - 1] = _KIND_CODES[join.kind]
            self._left_examples[index - 1] = join.left_example
            self._right_examples[index - 1] = join.right_example
        self._starts[index] = start
        self._ends[index] = end
        self._animes[index] = anime

    def reserve(self, placements: int, knots: int) -> TrackBuffers:
        """The buffers, whole, with room for ``placements`` more
        placements of ``knots`` more knots in all, for a compiled call to write them in place
        (join ``i`` into placement ``i + 1``, as ``_KIND_CODES``, and each placement's knots
        after the last, closing ``knot_offsets``); ``commit`` then counts them."""
        count = self._count + placements
        if count >= len(self._starts) or self._knots + knots > len(self._knot_targets):
            self._grow(count + 1, self._knots + knots)
        return self._buffers

    @property
    def buffers(self) -> TrackBuffers:
        """The buffers as they are (``len(self)`` placements, ``knots`` knots in use)."""
        return self._buffers

    def _gather(self) -> TrackBuffers:
        return TrackBuffers(
            self._starts,
            self._ends,
            self._animes,
            self._knot_offsets,
            self._knot_targets,
            self._knot_sources,
            self._join_kinds,
            self._left_examples,
            self._right_examples,
        )

    def commit(self, placements: int, knots: int) -> None:
        """Count ``placements`` placements and ``knots`` knots written after ``reserve``."""
        self._count += placements
        self._knots += knots

    @property
    def knots(self) -> int:
        """Knots held (``knot_targets`` entries in use)."""
        return self._knots

    def _close_knots(self, stop: int) -> None:
        self._knots = stop
        self._count += 1
        self._knot_offsets[self._count] = stop

    def _grow(self, placements: int, knots: int) -> None:
        """Double the buffers until they hold ``placements`` placements and ``knots`` knots."""
        rows = max(placements, 2 * len(self._starts))
        resized = (
            "_starts",
            "_ends",
            "_animes",
            "_join_kinds",
            "_left_examples",
            "_right_examples",
        )
        for name in resized:
            setattr(self, name, _resized(getattr(self, name), rows))
        self._knot_offsets = _resized(self._knot_offsets, rows + 1)
        if knots > len(self._knot_targets):
            rows = max(knots, 2 * len(self._knot_targets))
            self._knot_targets = _resized(self._knot_targets, rows)
            self._knot_sources = _resized(self._knot_sources, rows)
        self._buffers = self._gather()

    def evaluate(self, times: np.ndarray, left_continuous: bool = False) -> np.ndarray:
        """Track values (n, n_pc) at ascending ``times``; a time belongs to the last
        placement starting at or before it (``left_continuous``: strictly before it)."""
        return evaluate_track(
            np.asarray(times, dtype=np.float64),
            self._buffers,
            self._count,
            self._knots,
            self.motion,
            left_continuous,
        )


def _resized(values: np.ndarray, rows: int) -> np.ndarray:
    """``values`` in a buffer of ``rows`` (>= its length) rows, zeros after them."""
    if rows == len(values):
        return values
    grown = np.zeros(rows, dtype=values.dtype)
    grown[: len(values)] = values
    return grown


@njit(cache=True)
def evaluate_track(
    times: np.ndarray,
    track: TrackBuffers,
    count: int,
    knots: int,
    motion: AnimeMotion,
    left_continuous: bool,
) -> np.ndarray:
    """Each time's fragment value on the first ``count`` placements of ``track`` (``knots``
    knots) plus the corrections of the joins on either side:
    out = base + w_left (left - base) + w_right (right - base), w clipped to [0, 1]."""
    starts, joins = track.starts[:count], max(count - 1, 0)
    knot_targets, knot_sources = track.knot_targets[:knots], track.knot_sources[:knots]
    join_kinds, animes = track.join_kinds, track.animes
    values, offsets, utterance, rate = motion.values, motion.offsets, motion.utterance, motion.rate
    out = np.empty((len(times), values.shape[1]))
    base = np.empty(values.shape[1])
    other = np.empty(values.shape[1])
    for row in range(len(times)):
        time = times[row]
        if left_continuous:
            index = max(np.searchsorted(starts, time, side="left") - 1, 0)
        else:
            index = max(np.searchsorted(starts, time, side="right") - 1, 0)
        low, high = track.knot_offsets[index], track.knot_offsets[index + 1]
        recording = np.interp(time, knot_targets[low:high], knot_sources[low:high])
        sample_into(base, values, offsets, utterance[animes[index]], recording, rate, True)
        out[row] = base
        for side in range(2):
            join = index - 1 if side == 0 else index
            if join < 0 or join >= joins:
                continue
            kind = join_kinds[join]
            if kind == SEAMLESS_CODE or kind == CUT_CODE or (kind == _FORWARD and side == 1):
                continue
            example = track.right_examples[join] if side == 0 else track.left_examples[join]
            weight, anime, recording = _correction(side, kind, time, index, example, track, motion)
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
    example: int,
    track: TrackBuffers,
    motion: AnimeMotion,
) -> tuple[float, int, float]:
    """(weight, anime, recording time) of the correction from the left (``side`` 0) or
    right (1) join of placement ``index``: a pair example (anime ``example``) stretched onto
    the span, or the neighbour's recording extended across it."""
    starts, ends, animes = track.starts, track.ends, track.animes
    anime_start, anime_end = motion.start, motion.end
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
