"""Start-up measurement of what each model's incremental synthesis costs.

Method: a fixed calibration utterance (``CALIBRATION_PHONEMES`` phonemes
cycling through the canonical set, 80 ms each, at 60 fps) is streamed through
a rung's synthesizer one phoneme per ``feed``, followed by ``finish``, once
to warm up and then ``CALIBRATION_PASSES`` times measured. Each call's
time is its fastest over the passes (a call the scheduler preempted in one
pass is not slow in the next: preemption is the margin's part, not the
engine's), and the slowest call so taken is the rung's compute time (it
enters the latency estimate); the sum of those calls divided by the phonemes
is its per-phoneme cost. The cost of output frames is measured apart: the utterance
is synthesized offline at ``CALIBRATION_FPS`` and at ``FRAME_CALIBRATION_FPS``,
and the extra time (the fastest of the passes at each rate) over the extra
frames is the per-frame cost. Together they estimate a streaming call
(``engines.base.CallCost``), which decides whether a message is synthesized
inline or in the thread pool. An engine that uses audio is measured a second
time with a calibration signal fed alongside the phonemes (audio features,
DTW), and the costlier of the two counts: ``start`` does not say whether
audio will follow.

Bounds: a model that loads cleanly may still be absurdly costly (reordered
weights that disable a search's pruning made one calibrate for minutes and
price every session of every engine out). So every call runs under a
``WorkGuard`` (``calibration_guard``): a budget of CPU seconds for the whole
model, on a clock the caller may inject, checked between calls and inside the
engines' long loops. And once a rung's streaming cost is known, its
*session share* (the fraction of one core a session of real-time speech, one
phoneme per ``PHONEME_S``, needs) must not exceed the server's limit, checked
before the rest of the model is measured. Either failure is a
``ModelCostError`` (``model_too_costly``) naming the rung.

Probe: every frame calibration synthesizes, on every rung, streamed and
offline, with and without audio, must be finite. Load-time checks keep each
stored value in its documented range, but a combination of in-range values
may still overflow; such a model is refused with ``model_invalid`` at
``<model>: probe on rung <name>`` (``check_frames``) before any session can
ask it for frames.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..audio import Audio
from ..engines.base import MAX_FPS, CallCost, Model, Rung, SynthesisRequest, frame_count
from ..engines.work import WorkGuard
from ..errors import LipstreamError, ModelCostError, ModelStoreError
from ..phonemes import ARPABET
from ..timeline import PhonemeSpan

CALIBRATION_PHONEMES = 48
CALIBRATION_PASSES = 3
CALIBRATION_FPS = 60.0
FRAME_CALIBRATION_FPS = MAX_FPS
PHONEME_S = 0.08
CALIBRATION_RATE = 16_000


@dataclass(frozen=True)
class ComputeCost:
    """Measured milliseconds: the slowest incremental call, the mean cost per phoneme (at
    ``CALIBRATION_FPS``) and the cost of each further output frame."""

    max_call_ms: float
    per_phoneme_ms: float
    per_frame_ms: float = 0.0

    @property
    def call_cost(self) -> CallCost:
        return CallCost(self.per_phoneme_ms, self.per_frame_ms)

    @property
    def session_share(self) -> float:
        """The fraction of one core the engine needs for a session of real-time speech, one
        phoneme per ``PHONEME_S``."""
        return self.per_phoneme_ms / (1000.0 * PHONEME_S)


def calibration_guard(
    budget_s: float, where: str, clock: Callable[[], float] = time.thread_time
) -> WorkGuard:
    """The guard of one model's calibration: ``budget_s`` seconds of ``clock`` (by default
    the calibrating thread's CPU time), then ``ModelCostError`` at ``where``. Run the
    calibration inside its ``metering()``."""

    def exceeded(spent_s: float, budget: float) -> LipstreamError:
        return ModelCostError(
            f"its calibration used {spent_s:.3g} s of CPU, more than the {budget:g} s "
            "allowed (LIPSTREAM_CALIBRATION_CPU_S)",
            where=where,
        )

    return WorkGuard(budget_s, clock, exceeded)


def check_frames(frames: np.ndarray, where: str) -> None:
    """``ModelStoreError`` (``model_invalid``) at ``where`` unless every value of ``frames``
    (n_frames, n_channels) is finite."""
    finite = np.isfinite(frames)
    if not finite.all():
        frame, channel = np.unravel_index(int(np.argmin(finite)), frames.shape)
        raise ModelStoreError(
            f"synthesized {frames.size - int(finite.sum())} NaN or infinite values from the "
            f"calibration utterance (first at frame {frame}, channel {channel}): the model's "
            "stored values, each in its range, still combine into values the engine cannot use",
            where=where,
        )


def calibration_spans() -> list[PhonemeSpan]:
    return [
        PhonemeSpan(ARPABET[index % len(ARPABET)], index * PHONEME_S, (index + 1) * PHONEME_S)
        for index in range(CALIBRATION_PHONEMES)
    ]


def calibration_audio(spans: list[PhonemeSpan]) -> Audio:
    """A voiced-like signal under ``spans``: each span a tone with a harmonic, its pitch
    cycling with the phoneme, over faint noise (fixed seed)."""
    n_samples = round(spans[-1].end * CALIBRATION_RATE)
    times = np.arange(n_samples) / CALIBRATION_RATE
    owner = np.minimum((times / PHONEME_S).astype(np.int64), len(spans) - 1)
    pitch = 110.0 + 15.0 * (owner % 12)
    tone = 0.3 * np.sin(2 * np.pi * pitch * times) + 0.1 * np.sin(2 * np.pi * 2.7 * pitch * times)
    noise = np.random.default_rng(0).normal(0.0, 0.003, n_samples)
    return Audio((tone + noise).astype(np.float32), CALIBRATION_RATE)


def warm_up(
    model: Model, rung: Rung, guard: WorkGuard | None = None, where: str = "calibration"
) -> None:
    """Stream the calibration utterance through ``rung`` once, unmeasured (with the
    calibration audio too when the engine uses audio): an engine's first calls compile
    or load its kernels, which must not count as compute time. Its frames are probed
    (``check_frames`` at ``where: probe on rung <name>``)."""
    spans = calibration_spans()
    request = _request(CALIBRATION_FPS, rung, guard)
    probe = _probe_where(where, rung)
    _stream(model, request, spans, None, probe)
    if model.uses_audio:
        _stream(model, request, spans, calibration_audio(spans), probe)


def measure(
    model: Model,
    rung: Rung,
    guard: WorkGuard | None = None,
    max_share: float = math.inf,
    where: str = "calibration",
) -> ComputeCost:
    """Stream the calibration utterance through ``rung`` and time every call (with the
    calibration audio too when the engine uses audio; the costlier run counts).
    ``ModelCostError`` when ``guard``'s budget runs out, or (at ``where: rung <name>``)
    when the rung's session share exceeds ``max_share``, checked before the per-frame
    cost is measured; ``ModelStoreError`` when a frame is not finite (``check_frames``)."""
    spans = calibration_spans()
    audio = calibration_audio(spans) if model.uses_audio else None
    probe = _probe_where(where, rung)
    costs = [_measure_stream(model, rung, spans, None, guard, probe)]
    if audio is not None:
        costs.append(_measure_stream(model, rung, spans, audio, guard, probe))
    streaming = ComputeCost(
        max(cost.max_call_ms for cost in costs), max(cost.per_phoneme_ms for cost in costs)
    )
    if not streaming.session_share <= max_share:
        raise ModelCostError(
            f"a session of real-time speech on rung {rung.name} would need "
            f"{100 * streaming.session_share:.1f} % of a core ({streaming.per_phoneme_ms:.3g} ms "
            f"per {1000 * PHONEME_S:g} ms phoneme), more than the {100 * max_share:g} % allowed "
            "(LIPSTREAM_MAX_MODEL_SESSION_COST)",
            where=f"{where}: rung {rung.name}",
        )
    return ComputeCost(
        streaming.max_call_ms,
        streaming.per_phoneme_ms,
        _per_frame_ms(model, rung, spans, guard, probe),
    )


def _probe_where(where: str, rung: Rung) -> str:
    return f"{where}: probe on rung {rung.name}"


def _request(fps: float, rung: Rung, guard: WorkGuard | None) -> SynthesisRequest:
    if guard is None:
        return SynthesisRequest(fps=fps, options=dict(rung.options))
    return SynthesisRequest(fps=fps, options=dict(rung.options), guard=guard)


def _per_frame_ms(
    model: Model, rung: Rung, spans: list[PhonemeSpan], guard: WorkGuard | None, probe: str
) -> float:
    """Milliseconds per output frame: offline synthesis at two frame rates, the fastest of
    ``CALIBRATION_PASSES`` (after a warm-up) at each, the extra time over the extra frames."""
    times = []
    for fps in (CALIBRATION_FPS, FRAME_CALIBRATION_FPS):
        request = _request(fps, rung, guard)
        passes = [_offline(model, request, spans, probe) for _ in range(CALIBRATION_PASSES + 1)]
        times.append(min(passes[1:]))
    extra = frame_count(spans[-1].end, FRAME_CALIBRATION_FPS) - frame_count(
        spans[-1].end, CALIBRATION_FPS
    )
    return max(0.0, 1000.0 * (times[1] - times[0]) / extra)


def _offline(
    model: Model, request: SynthesisRequest, spans: list[PhonemeSpan], probe: str
) -> float:
    request.guard.check()
    started = time.perf_counter()
    synthesizer = model.start(request)
    synthesizer.feed(spans)
    frames = synthesizer.finish()
    elapsed = time.perf_counter() - started
    check_frames(frames, probe)
    return elapsed


def _measure_stream(
    model: Model,
    rung: Rung,
    spans: list[PhonemeSpan],
    audio: Audio | None,
    guard: WorkGuard | None,
    probe: str,
) -> ComputeCost:
    request = _request(CALIBRATION_FPS, rung, guard)
    _stream(model, request, spans, audio, probe)
    passes = np.array(
        [_stream(model, request, spans, audio, probe) for _ in range(CALIBRATION_PASSES)]
    )
    fastest = passes.min(axis=0)
    slowest = float(fastest.max())
    per_phoneme = float(fastest.sum()) / len(spans)
    return ComputeCost(1000.0 * slowest, 1000.0 * per_phoneme)


def _stream(
    model: Model,
    request: SynthesisRequest,
    spans: list[PhonemeSpan],
    audio: Audio | None,
    probe: str,
) -> list[float]:
    """Seconds spent in each call of one streamed pass; with ``audio``, each call also
    feeds the audio up to its span's end. The request's guard is checked before each call,
    and the frames of each at ``probe`` (``check_frames``)."""
    synthesizer = model.start(request)
    calls: list[float] = []
    sent = 0
    for span in spans:
        request.guard.check()
        chunk = None
        if audio is not None:
            until = min(len(audio.samples), round(span.end * audio.sample_rate))
            chunk, sent = Audio(audio.samples[sent:until], audio.sample_rate), until
        started = time.perf_counter()
        synthesizer.feed([span], chunk)
        frames = synthesizer.frames()
        calls.append(time.perf_counter() - started)
        check_frames(frames, probe)
    started = time.perf_counter()
    frames = synthesizer.finish()
    calls.append(time.perf_counter() - started)
    check_frames(frames, probe)
    return calls
