"""Streaming synthesis: observations → fixed-lag Viterbi → windowed trajectory → frames.

Three clocks. HMM frame j is at j / R (R = the model's ``hmm_fps``);
trajectory frame k at k / f, whose state is that of HMM frame ⌊k R / f⌋; output
frame i at i / fps is trajectory frame ⌊i f / fps⌋ (sample and hold). The solve
rate f (``HmmModel.solve_fps``) is the synthesis rate R_s (the training fps)
when fps ≥ R_s, as the recorded motion has no finer detail; below it, the
smallest whole multiple of fps that is at least R, so that every output frame
is a trajectory frame and no HMM frame lacks one (at 60 fps with R_s = 120:
f = 60, and the half of the R_s frames that would never be sent is not solved).
A frame at a time (B = 1, below) f stays R_s (``HmmModel.plan``).
The velocity statistics are rescaled to f (``trajectory``), so every rate solves
the same motion; trajectory frames at R_s and at f differ by the
discretisation only.

Observations of HMM frame j: the phoneme and emotion of the span with
start < j / R ≤ end (frame 0: the first span), known once the spans cover j / R
(audio alone: the request's emotion); on a plan with a bilabial lead (``Plan.lead_s``)
the spans are the articulatory ones (``bilabial_lead``: each /p b m/ starts up to the lead
earlier, its start final when it comes), so the phoneme is known once the spans cover
j / R + lead; and/or the
speech features of feature frame j (feature rate R), known once the audio
covers its window. On the rungs that may not wait for audio (``delay``) frame
j hears feature frame j − d instead, d frames being enough for its window to
have ended by j / R. Emission log-likelihood: the state's phoneme log-probability
and emotion log-probabilities plus its vocal Gaussian's log-density times
``audio_weight`` (a stream weight, as in multi-stream speech HMMs: 28 feature
dimensions would otherwise outvote the phoneme and the emotion), whichever the
request carries.

Driving (option ``drive``): ``phonemes``, ``audio``, ``both``, or ``auto``
(default), which decides at the request's first input: spans → phonemes
(audio fed later is ignored), audio → audio alone (spans fed later are an
error), both in one feed → both. A frame is decoded once, from the input then
final, so a streamed request that means both must say so up front.

Decoding: ``numerics.trellis.FixedLagViterbi`` with the rung's lag L (HMM
frames; None: commits only where survivors merge, and at the end).

Trajectory: blocks of B trajectory frames; block b is solved over frames
[bB − 2, (b+1)B + F) once their states are committed (F frames of future
context), its first two frames pinned to the committed ones
(``trajectory.solve``), and keeps [bB, (b+1)B). B = 1, F = 0 is a frame at a
time (``trajectory.recurse``, with the pose and velocity marginals, which keep that
recursion stable);
B None solves the whole utterance once at the end.

Finality: the output frame at t is final once the input covers
t + L / R + (B − 1 + F) / f, which guarantees its block is solvable; B and F are
chosen at f so that this wait is at most the one at R_s, the rung's lookahead. Every
decision depends only on the input up to then, so streaming in any chunking
gives the offline frames.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ...audio import Audio
from ...bilabial_lead import led_pair
from ...errors import InvalidRequestError
from ...features import speech_features
from ...numerics.banded import check_block_tridiagonal
from ...numerics.trellis import FixedLagViterbi
from ...phonemes import PHONEME_INDEX
from ...timeline import PhonemeSpan
from ..base import (
    AUDIO_ONLY_UNSUPPORTED,
    DEFAULT_EMOTION,
    SynthesisRequest,
    Synthesizer,
    fill_gaps,
    frame_count,
)
from ..growable import Growable
from ..streamed_features import StreamedFeatures
from . import kernels
from .serving import HmmServing

PINNED = 2
AUTO, PHONEMES, AUDIO, BOTH = "auto", "phonemes", "audio", "both"
DRIVES = (AUTO, PHONEMES, AUDIO, BOTH)
_EPS = kernels.EPS


@dataclass(frozen=True)
class Plan:
    """A rung's schedule: Viterbi lag (HMM frames, None: unlimited), block and future
    context (trajectory frames at ``rate``; block None: one solve at the end), feature delay
    (frames), the rate the trajectory is solved at (Hz), the drive, and the bilabial lead
    (s) of the phonemes read (``HmmModel.leads``)."""

    lag: int | None
    block: int | None
    future: int
    delay: int
    rate: float
    drive: str = AUTO
    lead_s: float = 0.0

    def wait_s(self, hmm_fps: float) -> float | None:
        """Seconds of input past t that the frame at t waits for (None: the end)."""
        if self.lag is None or self.block is None:
            return None
        return self.lag / hmm_fps + (self.block - 1 + self.future) / self.rate


def hmm_frame(k: np.ndarray | int, ratio: float) -> np.ndarray:
    """The HMM frame of trajectory frame(s) ``k`` (ratio = R / f)."""
    return np.floor(np.asarray(k, dtype=np.float64) * ratio + _EPS).astype(np.int64)


class HmmSynthesizer(Synthesizer):
    """One request: its observations, the decoder, and the trajectory solved so far, each
    in a buffer that grows at its end (the compiled steps in ``kernels`` read and write
    them in place, so a streamed call costs the same however long the request is)."""

    def __init__(self, model: HmmServing, request: SynthesisRequest, plan: Plan) -> None:
        self.model = model
        self.request = request
        self.plan = plan
        self.rate = plan.rate
        self.ratio = model.hmm_fps / plan.rate
        self.step = plan.rate / request.fps
        self.dynamics = model.dynamics_at(plan.rate)
        self.stepwise_dynamics = model.dynamics_at(plan.rate, coupled=False)
        self.spans: list[PhonemeSpan] = []
        self.end = 0.0
        self.span_rows = Growable(np.float64, (3,))  # start, phoneme row, emotion row
        self.led: PhonemeSpan | None = None  # the last span with its articulatory start
        width = model.vocal.dim if model.vocal else 0
        self.audio = StreamedFeatures(
            model.mfcc, width, speech_features, lookback=1, normalizer=model.normalizer()
        )
        self.heard = False
        self._drive(None if plan.drive == AUTO else plan.drive)
        self.decoder = FixedLagViterbi(
            model.log_start, model.log_transition, plan.lag, model.predecessors
        )
        self.observed = 0
        self.unheard = np.zeros((0, len(model.log_start)))
        self.states = Growable(np.int64)
        self.curve = Growable(np.float64, (self.dynamics.dim,))
        self.emitted = 0
        self.wait_s = plan.wait_s(model.hmm_fps)
        self.mood = model.emotion_row(request.emotion or DEFAULT_EMOTION)
        self.finished = False
        self.stats = {"frames": 0, "states": 0}

    @property
    def held_input_bytes(self) -> int:
        return self.audio.held_bytes

    def held_input_bytes_after(self, n_samples: int, sample_rate: int) -> int:
        if self.model.vocal is None or self.mode == PHONEMES:
            return 0  # audio this request takes is not kept
        return self.audio.held_bytes_after(n_samples, sample_rate)

    # -- input ------------------------------------------------------------------------------

    def _drive(self, mode: str | None) -> None:
        self.mode = mode
        self.reading = mode in (PHONEMES, BOTH)
        self.listening = mode in (AUDIO, BOTH)

    def span_position(self) -> tuple[float, int]:
        return self.end, len(self.spans)

    def take(self, spans: Sequence[PhonemeSpan], audio: Audio | None) -> None:
        covered, new = self.end, spans
        hearing = audio is not None and self.model.vocal is not None
        if self.mode is None and (new or hearing):
            self._drive(BOTH if new and hearing else (PHONEMES if new else AUDIO))
        if new and self.mode == AUDIO:
            raise InvalidRequestError(
                "this request is driven by audio alone (its first input was audio); to drive "
                "it by phonemes and audio, start it with options.drive = both",
                where="phonemes",
            )
        if new:
            emotion, rows, model = self.request.emotion, self.span_rows, self.model
            for span in fill_gaps(new, covered):
                self.spans.append(span)
                mood = span.emotion or emotion
                mood_row = model.emotion_row(mood) if mood else self.mood
                rows.append((self._start(span), PHONEME_INDEX[span.phoneme], mood_row))
            self.end = self.spans[-1].end
        if audio is not None:
            self.heard = True
            if hearing and self.mode != PHONEMES:
                self.audio.add(audio)

    def _start(self, span: PhonemeSpan) -> float:
        """``span``'s start as the phonemes are read: with a bilabial lead its articulatory
        start (``bilabial_lead.led_pair``), which needs only the span before it."""
        if self.plan.lead_s <= 0.0:
            return span.start
        if self.led is not None:
            _, span = led_pair(self.led, span, self.plan.lead_s)
        self.led = span
        return span.start

    def _duration(self) -> float:
        if self.reading:
            return self.end
        return self.audio.duration if self.listening else 0.0

    def _observable(self) -> int:
        """HMM frames whose observations are final."""
        hmm_fps = self.model.hmm_fps
        if self.finished:
            duration = self._duration()
            return frame_count(duration, hmm_fps) if duration > 0 else 0
        limit = None
        if self.reading:  # a bilabial starting within the lead after j / R takes frame j
            limit = max(0, frame_count(self.end - self.plan.lead_s, hmm_fps)) if self.spans else 0
        if self.listening:
            heard = self.audio.covered + self.plan.delay
            limit = heard if limit is None else min(limit, heard)
        return 0 if limit is None else limit

    def _covered_s(self) -> float:
        """The time up to which the input is final."""
        covered = math.inf if self.reading or self.listening else -math.inf
        if self.reading:
            covered = self.end - self.plan.lead_s if self.spans else -math.inf
        if self.listening:
            heard = (self.audio.covered + self.plan.delay - 1) / self.model.hmm_fps
            covered = min(covered, heard)
        return covered

    # -- observations and decoding ----------------------------------------------------------

    def _audio_terms(self, first: int, stop: int) -> tuple[np.ndarray, int]:
        """The weighted vocal log-densities of the HMM frames first .. stop − 1 that hear a
        feature frame, and the first of them (``kernels.emissions``)."""
        model = self.model
        if not self.listening or model.vocal is None:
            return self.unheard, 0
        frames = np.arange(first, stop) - self.plan.delay
        available = frame_count(self.audio.duration, model.mfcc.rate)
        heard = (frames < available) & (frames >= 0)  # the first d frames hear nothing yet
        if not heard.any():
            return self.unheard, 0
        wanted = frames[heard]
        lowest = int(wanted.min())
        past = int(wanted.max()) + 1
        rows = self.audio.through(past)[lowest:past].astype(np.float64)  # computed once each
        vocal = model.vocal.log_density(rows[wanted - lowest])
        return model.audio_weight * vocal, first + int(np.argmax(heard))

    def _decode(self) -> None:
        target = self._observable()
        states = self.states
        first = self.observed
        if target > first:
            self.request.guard.check()
            decoder, model = self.decoder, self.model
            decoding = decoder.reserve(target - first)
            out = states.reserve(decoder.most_committed(target - first))
            terms, heard_from = self._audio_terms(first, target)
            spans = self.span_rows
            fresh = model.decode_step(
                spans.data,
                spans.count if self.reading else 0,
                first,
                target,
                model.hmm_fps,
                model.categories,
                self.mood,
                terms,
                heard_from,
                decoding,
                out,
                states.count,
            )
            self.observed = target
            states.grow(fresh)
        if self.finished:
            states.extend(self.decoder.finish())
        self.stats["states"] = states.count

    # -- trajectory -------------------------------------------------------------------------

    def _synthesis_total(self) -> int | None:
        if not self.finished:
            return None
        duration = self._duration()
        return frame_count(duration, self.rate) if duration > 0 else 0

    def _ready_synthesis_frames(self) -> int:
        """Trajectory frames whose state is committed."""
        if not self.states.count:
            return 0
        return math.ceil((self.states.count - _EPS) / self.ratio)

    def _solve(self) -> None:
        total = self._synthesis_total()
        ready = self._ready_synthesis_frames() if total is None else total
        block = self.plan.block
        if block == 1:  # a frame at a time: every ready frame at once
            if ready > self.curve.count:
                self.request.guard.check()
                self._recurse(self.curve.count, ready)
            return
        while True:
            start = self.curve.count
            if total is not None and start >= total:
                return
            if block is None:
                if total is None:
                    return
                stop = end = total
            else:
                stop = start + block
                end = stop + self.plan.future
                if total is not None:
                    stop, end = min(stop, total), min(end, total)
            if end > ready:
                return
            self.request.guard.check()
            terms, curve = self.dynamics, self.curve
            check_block_tridiagonal(
                self.model.solve_step(
                    self.states.data,
                    self.states.count,
                    self.ratio,
                    curve.reserve(stop - start),
                    max(0, start - PINNED),
                    start,
                    stop,
                    end,
                    terms.blocks,
                )
            )
            curve.grow(stop - start)

    def _recurse(self, start: int, stop: int) -> None:
        """Frames start .. stop − 1 a frame at a time (``trajectory.recurse``)."""
        terms = self.stepwise_dynamics
        kernels.recurse(
            self.states.data,
            self.states.count,
            self.ratio,
            self.curve.reserve(stop - start),
            start,
            stop,
            terms.current_inverse,
            terms.g_cross,
            terms.r_current,
            terms.pose_mean,
        )
        self.curve.grow(stop - start)

    # -- output -----------------------------------------------------------------------------

    def _final_output_frames(self) -> int:
        fps = self.request.fps
        if self.finished:
            duration = self._duration()
            return frame_count(duration, fps) if duration > 0 else 0
        wait = self.wait_s
        if wait is None:
            return 0
        covered = self._covered_s()
        return 0 if covered < wait else frame_count(covered - wait, fps)

    def _emit(self) -> np.ndarray:
        stop = self._final_output_frames()
        if stop <= self.emitted:
            return np.zeros((0, len(self.model.channels)), dtype=np.float32)
        self._decode()
        self._solve()
        curve, basis = self.curve, self.model.basis
        frames = kernels.output_frames(
            curve.data, curve.count, self.emitted, stop, self.step, basis.components, basis.mean
        )
        self.emitted += len(frames)
        self.stats["frames"] = self.emitted
        return frames

    def frames(self) -> np.ndarray:
        return self._emit()

    def finish(self) -> np.ndarray:
        if self.mode == BOTH and not (self.spans and self.audio.length):
            raise InvalidRequestError(
                "a request with options.drive = both needs phonemes and audio", where="input"
            )
        if not self.spans and self.heard and self.model.vocal is None:
            raise InvalidRequestError(
                f"model {self.model.name!r} of engine hmm was trained without audio, so it "
                "cannot be driven by audio alone; send phonemes (with or without audio)",
                where="audio",
                code=AUDIO_ONLY_UNSUPPORTED,
            )
        self.finished = True
        return self._emit()
