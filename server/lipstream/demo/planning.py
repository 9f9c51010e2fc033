"""Articulatory planning: from phoneme spans to a target timeline per articulator.

Sketch:
1. Spans become *segments*, one per articulatory target (diphthongs give two);
   gaps become silence, and a silence longer than the look-ahead horizon is
   split so the lips can prepare for the first word during the pause.
2. Each segment gets one value per articulator inside its window. A narrow
   window's centre is a requirement. A wide window is resolved by context:
   jaw and lip aperture take the straight-line path between the surrounding
   requirements (Keating's window model); rounding and spreading use the
   look-ahead model (Henke): a free segment already takes the next requirement
   if that begins within the horizon, so rounding for /uw/ starts during the
   consonants before it; beyond the horizon the lips relax to neutral.
3. Each articulator switches to a segment's target a little before its
   acoustic start (gestures lead their sound, closures most), but keeps a
   requirement for the first half of its segment, and a contact (lips
   together, lip on teeth) for its first 40%, before moving on. The leads and
   the hold are calibrated to real faces (``lipstream.bench.demo_calibration``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import InvalidRequestError
from ..phonemes import SILENCE
from ..timeline import PhonemeSpan
from .targets import (
    DIPHTHONG_SPLIT,
    N_ARTICULATORS,
    Articulator,
    GestureTarget,
    gesture_targets,
)

INTERPOLATED = (Articulator.JAW, Articulator.LIPS, Articulator.TUCK)
ANTICIPATED = (Articulator.ROUND, Articulator.SPREAD)
CONTACT_ARTICULATORS = (Articulator.LIPS, Articulator.TUCK)

GESTURE_LEAD_S = np.array([0.035, 0.040, 0.0, 0.045, 0.040])
"""How long before a segment's acoustic start each articulator heads for it (s); rounding
heads for it at the start itself, as real lips are halfway round at a rounded vowel's onset."""
CONTACT_LEAD_S = 0.1
"""Lips head for a contact earlier: real lips are shut by the acoustic start of /p b m/."""
CONTACT_HOLD = 0.4
"""Fraction of a contact segment the lips stay on target before releasing."""
REQUIRED_SHARE = 0.5
"""Fraction of a segment an articulator it constrains keeps before moving on."""


@dataclass(frozen=True)
class Segment:
    """One articulatory target over [start, end) seconds, from ``phoneme``."""

    phoneme: str
    start: float
    end: float
    target: GestureTarget

    @property
    def centre(self) -> float:
        return 0.5 * (self.start + self.end)


def _check_times(spans: Sequence[PhonemeSpan], duration_s: float) -> None:
    if not (np.isfinite(duration_s) and duration_s > 0):
        raise InvalidRequestError(
            f"duration must be positive, got {duration_s}", where="duration_s"
        )
    for index, span in enumerate(spans):
        if not (np.isfinite(span.start) and np.isfinite(span.end)):
            raise InvalidRequestError("span times must be finite", where=f"spans[{index}]")


def _targets_of(span: PhonemeSpan, start: float, end: float, where: str) -> list[Segment]:
    targets = gesture_targets(span.phoneme, where)
    if len(targets) == 1:
        return [Segment(span.phoneme, start, end, targets[0])]
    middle = start + DIPHTHONG_SPLIT * (end - start)
    return [
        Segment(span.phoneme, start, middle, targets[0]),
        Segment(span.phoneme, middle, end, targets[1]),
    ]


def _split_long_silence(segment: Segment, horizon_s: float) -> list[Segment]:
    if segment.phoneme != SILENCE or segment.end - segment.start <= 2 * horizon_s:
        return [segment]
    cut = segment.end - horizon_s
    return [
        Segment(SILENCE, segment.start, cut, segment.target),
        Segment(SILENCE, cut, segment.end, segment.target),
    ]


def build_segments(
    spans: Sequence[PhonemeSpan], duration_s: float, horizon_s: float
) -> list[Segment]:
    """Segments covering [0, ``duration_s``] without gaps, in time order."""
    _check_times(spans, duration_s)
    silence = gesture_targets(SILENCE)[0]
    raw: list[Segment] = []
    cursor = 0.0
    for index, span in enumerate(sorted(spans, key=lambda item: item.start)):
        start, end = max(span.start, cursor), min(span.end, duration_s)
        if end <= start:
            continue
        if start > cursor:
            raw.append(Segment(SILENCE, cursor, start, silence))
        raw.extend(_targets_of(span, start, end, f"spans[{index}]"))
        cursor = end
    if cursor < duration_s:
        raw.append(Segment(SILENCE, cursor, duration_s, silence))
    return [piece for segment in raw for piece in _split_long_silence(segment, horizon_s)]


@dataclass(frozen=True)
class TargetPlan:
    """Per segment and articulator: ``values`` and ``narrow`` (a requirement), and
    ``onsets`` (s) when the articulator starts heading for that value, all of
    shape (n_segments, n_articulators); ``contact`` (n_segments,) marks segments
    whose lips must touch."""

    values: np.ndarray
    narrow: np.ndarray
    onsets: np.ndarray
    contact: np.ndarray


def _windows(segments: Sequence[Segment]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    bounds = np.array([segment.target.windows for segment in segments], dtype=np.float64)
    low, high = bounds[:, :, 0], bounds[:, :, 1]
    narrow = np.array(
        [[segment.target.is_narrow(a) for a in Articulator] for segment in segments], dtype=bool
    )
    return low, high, narrow


def _interpolated(centres: np.ndarray, middle: np.ndarray, narrow: np.ndarray) -> np.ndarray:
    if not narrow.any():
        return middle
    return np.asarray(np.interp(centres, centres[narrow], middle[narrow]))


def _anticipated(
    starts: np.ndarray, middle: np.ndarray, narrow: np.ndarray, horizon_s: float
) -> np.ndarray:
    required = np.flatnonzero(narrow)
    if required.size == 0:
        return np.zeros_like(middle)
    following = np.searchsorted(required, np.arange(len(starts)), side="left")
    next_index = required[np.minimum(following, required.size - 1)]
    within = (following < required.size) & (starts[next_index] - starts <= horizon_s + 1e-9)
    return np.where(within, middle[next_index], 0.0)


def _resolve_values(segments: Sequence[Segment], horizon_s: float) -> tuple[np.ndarray, np.ndarray]:
    low, high, narrow = _windows(segments)
    middle = 0.5 * (low + high)
    starts = np.array([segment.start for segment in segments])
    centres = np.array([segment.centre for segment in segments])
    context = np.empty_like(middle)
    for articulator in INTERPOLATED:
        context[:, articulator] = _interpolated(
            centres, middle[:, articulator], narrow[:, articulator]
        )
    for articulator in ANTICIPATED:
        context[:, articulator] = _anticipated(
            starts, middle[:, articulator], narrow[:, articulator], horizon_s
        )
    values = np.where(narrow, middle, np.clip(context, low, high))
    return values, narrow


def _onsets(segments: Sequence[Segment], narrow: np.ndarray, contact: np.ndarray) -> np.ndarray:
    starts = np.array([segment.start for segment in segments])
    durations = np.array([segment.end for segment in segments]) - starts
    onsets = starts[:, None] - GESTURE_LEAD_S[None, :]
    for articulator in CONTACT_ARTICULATORS:
        onsets[contact, articulator] = starts[contact] - CONTACT_LEAD_S
    share = np.where(narrow, REQUIRED_SHARE, 0.0)
    for articulator in CONTACT_ARTICULATORS:
        share[contact, articulator] = CONTACT_HOLD
    kept_until = starts[:, None] + share * durations[:, None]
    onsets[1:] = np.maximum(onsets[1:], kept_until[:-1])
    onsets[0, :] = -np.inf
    return np.maximum.accumulate(onsets, axis=0)


def plan_targets(segments: Sequence[Segment], horizon_s: float) -> TargetPlan:
    """Resolve windows to values and schedule the onsets (see the module sketch)."""
    if not segments:
        raise InvalidRequestError("nothing to plan: no segments", where="spans")
    values, narrow = _resolve_values(segments, horizon_s)
    contact = np.array([segment.target.contact for segment in segments], dtype=bool)
    return TargetPlan(
        values=values, narrow=narrow, onsets=_onsets(segments, narrow, contact), contact=contact
    )


def sample_plan(onsets: np.ndarray, per_segment: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Hold each segment's value from its onset: shape (len(times), n_articulators)."""
    sampled = np.empty((len(times), N_ARTICULATORS), dtype=np.float64)
    for articulator in range(N_ARTICULATORS):
        active = np.searchsorted(onsets[:, articulator], times, side="right") - 1
        sampled[:, articulator] = per_segment[np.maximum(active, 0), articulator]
    return sampled
