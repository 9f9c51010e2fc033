"""Streaming a critically damped filter that follows each phoneme's target pose.

Method: the target at time τ is the pose of the phoneme spoken at τ + lead,
a step function of time whose steps sit at the span starts shifted by
-lead; each phoneme also sets the filter's rate ω. Frame i (time t_i) is the
filter's value after stepping exactly through every step between t_{i-1} and
t_i (``damped``), from rest at the target of t = 0. So the frame at t needs
the input up to t + lead and no further: it is emitted as soon as the input
covers it, and since the state is carried frame to frame through the same
pieces whatever the chunking, streaming gives the offline frames. Past the
end of the input the last phoneme's target holds.
"""

from __future__ import annotations

from bisect import bisect_right
from dataclasses import dataclass

import numpy as np

from ..phonemes import PHONEME_INDEX
from ..timeline import PhonemeSpan
from .base import SpanSynthesizer, SynthesisRequest, frame_count, shifted_frame_stop
from .damped import DampedState


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
        self._shifted: list[float] = []
        self._rows: list[int] = []
        self.state: DampedState | None = None

    def _accepted(self, span: PhonemeSpan, sent: int | None) -> None:
        self._shifted.append(span.start - self.targets.lead_s)
        self._rows.append(PHONEME_INDEX[span.phoneme])

    def frames(self) -> np.ndarray:
        return self._emit(shifted_frame_stop(self, self.targets.lead_s, self.fps))

    def finish(self) -> np.ndarray:
        self.finished = True
        return self._emit(frame_count(self.covered_until, self.fps) if self.spans else 0)

    def _span_at(self, shifted_time: float) -> int:
        """Index of the span whose target holds at (shifted) ``shifted_time``."""
        return max(0, bisect_right(self._shifted, shifted_time) - 1)

    def _emit(self, stop: int) -> np.ndarray:
        if stop <= self.emitted:
            return np.zeros((0, len(self.channels)), dtype=np.float32)
        self.request.guard.check()
        times = np.arange(self.emitted, stop, dtype=np.float64) / self.fps
        pieces: list[np.ndarray] = []
        if self.state is None:
            self.state = DampedState.at_rest(
                self.targets.poses[self._rows[self._span_at(0.0)]], 0.0
            )
            pieces.append(self.state.x[None].copy())
            times = times[1:]
        if len(times):
            pieces.append(self._advance(times))
        self.emitted = stop
        self.stats["frames"] = stop
        return np.concatenate(pieces).astype(np.float32)

    def _advance(self, times: np.ndarray) -> np.ndarray:
        """Step the filter from its time to each of ``times`` (ascending, after it)."""
        state = self.state
        assert state is not None
        first = self._span_at(state.t)
        shifted = np.asarray(self._shifted[first:])
        rows = np.asarray(self._rows[first:], dtype=np.int64)
        steps = shifted[(shifted > state.t) & (shifted < times[-1])]
        points = np.union1d(times, steps)
        starts = np.concatenate(([state.t], points[:-1]))
        owners = np.maximum(np.searchsorted(shifted, starts, side="right") - 1, 0)
        phonemes = rows[owners]
        omegas = np.repeat(self.targets.omegas[phonemes][:, None], len(self.channels), axis=1)
        values = state.run(
            self.targets.poses[phonemes], omegas, points - starts, np.isin(points, times)
        )
        state.t = float(points[-1])
        return values
