"""The causal rungs of ``dam`` and ``cohen-massaro``: modes committed on arrival, Eq. 2 over
the spans that have begun, followed by a critically damped filter.

Method: spans arrive whole, so at time τ the input holds every span that starts
before τ. Span k's mode is committed when it arrives and never revised: the
search of ``selection`` restricted to the known prefix with the earlier modes
fixed (fixed lag 0), which leaves E_c of span k with its next phoneme unknown
plus E_s of its join to span k - 1's committed mode. The raw curve r(τ) is
Eq. 2 summed over the spans that start before τ (span 0 always; at most
``tail`` spans behind the span holding τ, each cut by its dominance reach, as
offline): no term anticipates a phoneme not yet heard. r jumps at every span
start, where a whole new term enters the sum, so the frames follow it with
the shared critically damped filter (``damped``), one per motion-basis
component (the same filter on every channel, since the basis is affine and
the filter has unit gain at rest), at ω = κ / the median duration of the
phoneme holding τ (``durations``, κ from ``damped_fit``). Frame i steps the
filter from frame i - 1 toward r at frame i held over the step; frame 0 starts
at rest on r(0).

A lead rung follows r(t + shift) instead, shift = min(lead, 2 d / κ) with d the
pooled median duration, to make up the filter's lag as viseme-lerp's damped
rung does; the causal rung is shift 0. The frame at t is final once the input
covers t + shift, and the state carried frame to frame does not depend on how
the input was cut, so streaming gives the offline frames.
"""

from __future__ import annotations

from bisect import bisect_left
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from ...phonemes import PHONEME_INDEX as CANONICAL_INDEX
from ...timeline import PhonemeSpan
from ..base import ShiftedSynthesizer, SynthesisRequest, fill_gaps, frame_count
from ..damped import DampedState, filter_raw
from ..damped_fit import best_kappa
from .dominance import dominance, powers
from .selection import context_cost, smooth_cost

if TYPE_CHECKING:
    from .model import DamModel

_STARTED = 1e-9
"""A span starting within this of τ has not begun at τ: the frame at a span's end is final
with that span's input."""


class CausalCurve:
    """The committed modes of one request and its raw curve r."""

    def __init__(self, model: DamModel, request: SynthesisRequest) -> None:
        self.model = model
        self.request = request
        self.positions: list[int] = []
        self.modes: list[int] = []
        self.starts: list[float] = []

    def commit(self, spans: Sequence[PhonemeSpan]) -> None:
        """Commit the mode of every span not yet committed, in order."""
        costs = self.model.costs
        for index in range(len(self.modes), len(spans)):
            layer = self.model.layer(spans, index, index, self.request)
            cost = costs.w_context * context_cost(costs, layer)
            if index > 0:
                before = self.model.layer(spans, index - 1, index - 1, self.request)
                joins = smooth_cost(costs, before, layer)
                cost = cost + costs.w_smooth * joins[self.positions[-1]]
            position = int(np.argmin(cost))
            self.positions.append(position)
            self.modes.append(int(layer.candidates[position]))
            self.starts.append(spans[index].start)

    def raw(self, spans: Sequence[PhonemeSpan], at: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """r at times ``at`` (ascending, components) and the index of the latest span begun at
        each; every span of ``spans`` is committed."""
        model = self.model
        low = max(0, bisect_left(self.starts, float(at[0]) - _STARTED) - 1)
        high = bisect_left(self.starts, float(at[-1]) - _STARTED)
        starts = np.asarray(self.starts[low:high])
        begun = low + np.maximum(np.searchsorted(starts, at - _STARTED, side="left") - 1, 0)
        first = max(0, int(begun[0]) - model.tail)
        values = np.zeros((len(at), model.coefficients.shape[2]))
        for k in range(first, int(begun[-1]) + 1):
            span, mode = spans[k], self.modes[k]
            local = (at - span.start) / (span.end - span.start)
            near = (begun >= k) & (begun - model.tail <= k)
            near &= (local >= -model.reach[mode]) & (local <= 1.0 + model.reach[mode])
            if near.any():
                u = local[near]
                weight = dominance(u, model.sigma[mode], model.eps)
                values[near] += weight[:, None] * (
                    powers(u, model.coefficients.shape[1] - 1) @ model.coefficients[mode]
                )
        return values, begun


def inverse_durations(
    model: DamModel, spans: Sequence[PhonemeSpan], indices: np.ndarray
) -> np.ndarray:
    """1 / the median duration (s) of the phoneme of each of the spans ``indices``."""
    phonemes = [CANONICAL_INDEX[spans[k].phoneme] for k in indices.tolist()]
    return np.asarray(1.0 / model.durations.expected_all_s()[phonemes])


class CausalSynthesizer(ShiftedSynthesizer):
    """One request of a causal or lead rung: the frame at t is final once the input covers
    t + shift; the filter's state is carried from call to call."""

    model: DamModel

    def __init__(self, model: DamModel, request: SynthesisRequest, shift_s: float) -> None:
        super().__init__(model, request)
        self.shift_s = shift_s
        self.curve = CausalCurve(model, request)
        self.state: DampedState | None = None

    def _emit(self, stop: int) -> np.ndarray:
        if stop <= self.emitted:
            return np.zeros((0, len(self.model.channels)), dtype=np.float32)
        self.request.guard.check()
        fps = self.request.fps
        times = np.arange(self.emitted, stop, dtype=np.float64) / fps
        self.curve.commit(self.spans)
        raw, begun = self.curve.raw(self.spans, times + self.shift_s)
        omegas = self.model.causal_kappa * inverse_durations(self.model, self.spans, begun)
        self.state, values = filter_raw(self.state, raw, omegas, times)
        self.emitted = stop
        self.stats["frames"] = stop
        return np.asarray(self.model.basis.reconstruct(values), dtype=np.float32)


def fit_causal_kappa(model: DamModel, utterances: Sequence[Any]) -> float:
    """The κ of ``KAPPAS`` whose causal rung has the least squared error on ``utterances``
    (``damped_fit``); each utterance's raw curve is computed once, the filter per κ."""
    curves: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}

    def synthesize(kappa: float, utterance: Any) -> np.ndarray:
        key = id(utterance)
        if key not in curves:
            request = SynthesisRequest(fps=float(utterance.fps), emotion=utterance.emotion)
            spans = fill_gaps(utterance.phones)
            times = np.arange(frame_count(spans[-1].end, request.fps)) / request.fps
            curve = CausalCurve(model, request)
            curve.commit(spans)
            raw, begun = curve.raw(spans, times)
            curves[key] = (raw, inverse_durations(model, spans, begun), times)
        raw, inverse, times = curves[key]
        _, values = filter_raw(None, raw, kappa * inverse, times)
        return model.basis.reconstruct(values)

    return best_kappa(synthesize, utterances)
