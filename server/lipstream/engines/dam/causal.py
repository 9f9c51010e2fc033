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

Cost: a server at lead 0 calls the synthesizer once per phoneme message, so
each call is one compiled call (``kernels.causal_run``): the modes of the
spans that arrived (``commit_modes``), the frames' raw curve (``causal_sum``,
the latest span begun found by binary search over the spans' starts), the
filter, and the motion basis, through the model's ``DirectCall``. The spans'
starts, ends, phonemes, emotions, modes and rates are kept in ``Growable`` arrays,
so a call converts only the spans it brought, and handed to the kernels as
``kernels.SpanArrays`` and the rates beside them.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ...timeline import PhonemeSpan
from ..base import ShiftedSynthesizer, SynthesisRequest, fill_gaps, frame_count
from ..damped import FilterState
from ..damped_fit import RawCurve, best_following_kappa
from ..growable import Growable
from .kernels import SpanArrays, causal_sum, commit_modes
from .modes import PHONEME_INDEX, emotion_index
from .serving import DamServing


class CausalCurve:
    """The committed modes of one request and its raw curve r, by the compiled kernels
    (``kernels.commit_modes``, ``kernels.causal_sum``); ``committed`` spans have their mode."""

    def __init__(self, model: DamServing, request: SynthesisRequest) -> None:
        self.model = model
        self.request = request
        self.starts = Growable(np.float64)
        self.ends = Growable(np.float64)
        self.phonemes = Growable(np.int64)
        self.emotions = Growable(np.int64)
        self.modes = Growable(np.int64)
        self.rates = Growable(np.float64)
        """1 / the median duration (s) of each span's phoneme: ω over κ."""
        self.committed = 0
        self._arrays = self._gather()

    def _gather(self) -> SpanArrays:
        return SpanArrays(
            self.starts.data,
            self.ends.data,
            self.phonemes.data,
            self.emotions.data,
            self.modes.data,
        )

    @property
    def count(self) -> int:
        """Spans added."""
        return self.starts.count

    @property
    def spans(self) -> SpanArrays:
        """The buffers whose first ``count`` rows hold the spans added (``rates`` beside)."""
        if self._arrays.starts is not self.starts.data:  # the buffers grow together
            self._arrays = self._gather()
        return self._arrays

    def add(self, spans: Sequence[PhonemeSpan]) -> None:
        """Take the arrays of the spans not yet added (their modes not yet committed)."""
        rates = self.model.span_rates
        for span in spans[self.starts.count :]:
            phoneme = PHONEME_INDEX[span.phoneme]
            self.starts.append(span.start)
            self.ends.append(span.end)
            self.phonemes.append(phoneme)
            self.emotions.append(emotion_index(self.request, span))
            self.modes.append(-1)
            self.rates.append(rates[phoneme])

    def commit(self, spans: Sequence[PhonemeSpan]) -> None:
        """Commit the mode of every span not yet committed, in order."""
        self.add(spans)
        commit_modes(self.committed, self.spans, self.count, self.model.tables.search)
        self.committed = self.modes.count

    def raw(self, at: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """r at times ``at`` (components) and 1 / the median duration of the latest span begun
        at each (the filter's ω over κ); the spans reaching ``at`` are committed."""
        tables = self.model.tables
        values, rates = causal_sum(
            at, self.spans, self.count, self.rates.data, tables.tail, tables.animemes
        )
        return np.asarray(values), np.asarray(rates)


class CausalSynthesizer(ShiftedSynthesizer):
    """One request of a causal or lead rung: the frame at t is final once the input covers
    t + shift; the filter's state is carried from call to call."""

    model: DamServing

    def __init__(self, model: DamServing, request: SynthesisRequest, shift_s: float) -> None:
        super().__init__(model, request)
        self.shift_s = shift_s
        self.curve = CausalCurve(model, request)
        # The filter's value and velocity per basis component, at rest before frame 0.
        self.state = FilterState(
            np.zeros(model.basis.n_components), np.zeros(model.basis.n_components)
        )

    def _emit(self, stop: int) -> np.ndarray:
        if stop <= self.emitted:
            return np.zeros((0, len(self.model.channels)), dtype=np.float32)
        self.request.guard.check()
        curve = self.curve
        curve.add(self.spans)
        frames: np.ndarray = self.model.causal_call(
            self.emitted,
            stop,
            float(self.request.fps),
            self.shift_s,
            self.state,
            curve.committed,
            curve.spans,
            curve.count,
            curve.rates.data,
            self.model.tables,
        )
        curve.committed = curve.modes.count
        self.emitted = stop
        self.stats["frames"] = stop
        return frames


def fit_causal_kappa(model: DamServing, utterances: Sequence[Any]) -> float:
    """The κ of ``KAPPAS`` whose causal rung has the least squared error on ``utterances``
    (``damped_fit``)."""

    def raw_curve(utterance: Any) -> RawCurve:
        request = SynthesisRequest(fps=float(utterance.fps), emotion=utterance.emotion)
        spans = fill_gaps(utterance.phones)
        times = np.arange(frame_count(spans[-1].end, request.fps)) / request.fps
        curve = CausalCurve(model, request)
        curve.commit(spans)
        raw, rates = curve.raw(times)
        return raw, rates, times

    return best_following_kappa(raw_curve, model.basis, utterances)
