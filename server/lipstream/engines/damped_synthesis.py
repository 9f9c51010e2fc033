"""Streaming a critically damped filter that follows each phoneme's target pose.

Method: the target at time τ is the pose of the phoneme spoken at τ + lead,
a step function of time whose steps sit at the span starts shifted by
-lead; each phoneme also sets the filter's rate ω. Frame i (time t_i) is the
filter's value after stepping exactly through every step between t_{i-1} and
t_i (``damped``), from rest at the target of t = 0. So the frame at t needs
the input up to t + lead and no further: it is emitted as soon as the input
covers it, and since the state is carried frame to frame through the same
pieces whatever the chunking, streaming gives the offline frames. Past the
end of the input the last phoneme's target holds. One compiled pass
(``_advance``) merges the frame times with the steps between them, so a call
costs a kernel dispatch rather than numpy set operations on a few numbers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ..phonemes import PHONEME_INDEX
from ..timeline import PhonemeSpan
from .base import SpanSynthesizer, SynthesisRequest, frame_count, shifted_frame_stop
from .damped import DampedState, step_toward
from .growable import Growable


@dataclass(frozen=True)
class DampedTargets:
    """Per phoneme (``PHONEMES`` order): the target pose ``poses`` (n_phonemes, n_channels)
    and the filter rate ``omegas`` (n_phonemes,) rad/s; ``lead_s`` how far ahead it looks."""

    poses: np.ndarray
    omegas: np.ndarray
    lead_s: float


class DampedTimelineSynthesizer(SpanSynthesizer):
    """One request of a damped rung: frames final once the input covers t + lead."""

    def __init__(
        self, targets: DampedTargets, request: SynthesisRequest, channels: tuple[str, ...]
    ) -> None:
        super().__init__()
        self.targets = targets
        self.request = request
        self.channels = channels
        self.fps = float(request.fps)
        self._shifted = Growable(np.float64)
        self._rows = Growable(np.int64)
        self._omega_rows = np.repeat(targets.omegas[:, None], len(channels), axis=1)
        self.state: DampedState | None = None

    def _accepted(self, span: PhonemeSpan, sent: int | None) -> None:
        self._shifted.append(span.start - self.targets.lead_s)
        self._rows.append(PHONEME_INDEX[span.phoneme])

    def frames(self) -> np.ndarray:
        return self._emit(shifted_frame_stop(self, self.targets.lead_s, self.fps))

    def finish(self) -> np.ndarray:
        self.finished = True
        return self._emit(frame_count(self.covered_until, self.fps) if self.spans else 0)

    def _emit(self, stop: int) -> np.ndarray:
        return self.advance_to(stop).astype(np.float32)

    def advance_to(self, stop: int) -> np.ndarray:
        """The frames from the last emitted to ``stop`` (exclusive) in float64; each must be
        covered by the input (``frames`` and ``finish`` emit them as float32)."""
        if stop <= self.emitted:
            return np.zeros((0, len(self.channels)))
        self.request.guard.check()
        values = np.empty((stop - self.emitted, len(self.channels)))
        first = self.emitted
        shifted = self._shifted.view()
        if self.state is None:
            owner = max(0, int(np.searchsorted(shifted, 0.0, side="right")) - 1)
            self.state = DampedState.at_rest(self.targets.poses[self._rows.view()[owner]], 0.0)
            values[0] = self.state.x
            first += 1
        if stop > first:
            state = self.state
            state.t = _advance(
                state.x,
                state.v,
                state.t,
                shifted,
                self._rows.view(),
                first,
                stop,
                self.fps,
                self.targets.poses,
                self._omega_rows,
                values[first - self.emitted :],
            )
        self.emitted = stop
        self.stats["frames"] = stop
        return values


@njit(cache=True)
def _advance(
    x: np.ndarray,
    v: np.ndarray,
    t: float,
    shifted: np.ndarray,
    rows: np.ndarray,
    first: int,
    stop: int,
    fps: float,
    poses: np.ndarray,
    omega_rows: np.ndarray,
    out: np.ndarray,
) -> float:
    """Step the filter from ``t`` through frames ``first`` .. ``stop`` - 1 (at k / fps, each
    after ``t``), recording each in ``out``, and through every step of the targets between
    (``shifted`` ascending; the span of ``rows[j]`` holds from ``shifted[j]``, the first span
    also before it): one merged pass, a step at a frame's time taken with the frame. The
    time of the last frame."""
    count = len(shifted)
    following = int(np.searchsorted(shifted, t, side="right"))
    now = t
    for row in range(stop - first):
        frame_t = (first + row) / fps
        while following < count and shifted[following] < frame_t:
            owner = rows[max(following - 1, 0)]
            step_toward(x, v, poses[owner], omega_rows[owner], shifted[following] - now)
            now = shifted[following]
            while following < count and shifted[following] <= now:
                following += 1
        owner = rows[max(following - 1, 0)]
        step_toward(x, v, poses[owner], omega_rows[owner], frame_t - now)
        now = frame_t
        while following < count and shifted[following] <= now:
            following += 1
        out[row] = x
    return now
