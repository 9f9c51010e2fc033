"""Baseline ``viseme-lerp``: static viseme key poses, linearly interpolated.

Method (what most lip-sync tools do): each viseme class gets one key pose,
the mean of every training frame that falls inside a phoneme of that class.
At synthesis a key is placed at the centre of each phoneme span and the
channels are interpolated linearly between consecutive centres, holding the
first and last keys flat. Every other engine is measured against this one.

Fidelity ladder: the interpolation waits for the centre of the next span.
Below it, ``mode: damped`` rungs follow the key pose of the span at t + shift
with a critically damped filter (``damped``), each phoneme's rate
ω = κ / its median duration (``durations``), so a short closure is reached
within its span. The shift makes up the filter's lag (2 / ω at low
frequencies, taken at the pooled median duration) as far as the rung's lead
allows: shift = min(lead, 2 d / κ), never more, since a target moved ahead of
its phoneme skips short closures. The frame at t is final once the input
covers t + shift.
The rungs' leads are ``LEADS_MS``: ``damped_lead`` (at most 120 ms) and
``causal`` (0, the floor); κ of each is the
value of ``KAPPAS`` with the least squared error on training utterances
(``damped_fit``), stored in the model.

Stored ranges (checked at load): key poses within ``MAX_MAGNITUDE``; leads in
[0, 1000] ms; κ in [0.1, 100] (``KAPPA_RANGE``); durations as in
``durations``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..audio import Audio
from ..errors import CorpusError, InvalidRequestError, LipstreamError
from ..model_checks import ArrayReader, FieldReader
from ..phonemes import PHONEMES, SILENCE
from ..store import ARRAYS_NAME, MANIFEST_NAME, ModelManifest
from ..timeline import PhonemeSpan
from ..visemes import get_scheme
from .base import (
    MAX_LEAD_MS,
    Engine,
    Lookahead,
    RenderingModel,
    RenderingSynthesizer,
    Rung,
    SynthesisRequest,
    Synthesizer,
    lead_ms_option,
    resolved_rung,
)
from .damped_fit import KAPPA_RANGE, KAPPAS, best_kappa, validation_utterances
from .damped_synthesis import DampedTargets, DampedTimelineSynthesizer
from .durations import DurationModel
from .lerp_keys import KeyedSpans, lerp_frames

MODES = ("lerp", "damped")
LEADS_MS = (120.0, 0.0)


class VisemeLerpModel(RenderingModel):
    """Key poses ``poses`` float32 (n_visemes, n_channels), rows in ``scheme.classes`` order;
    phoneme ``durations``; the damped rungs' ``leads_ms`` and their fitted ``kappas``."""

    engine = "viseme-lerp"
    option_names = ("mode", "lead_ms")

    def __init__(
        self,
        manifest: ModelManifest,
        poses: np.ndarray,
        durations: DurationModel,
        leads_ms: np.ndarray,
        kappas: np.ndarray,
    ) -> None:
        super().__init__(manifest)
        self.scheme = get_scheme(manifest.hyperparameters["scheme"])
        # A small copy, not the memmap: fancy indexing off a memmap is slow.
        self.poses = np.array(poses, dtype=np.float32)
        self._pose_row = {p: self.scheme.classes.index(self.scheme.viseme_of(p)) for p in PHONEMES}
        self.durations = durations
        self.leads_ms = np.array(leads_ms, dtype=np.float64)
        self.kappas = np.array(kappas, dtype=np.float64)
        self._pose_rows = np.array([self._pose_row[p] for p in PHONEMES], dtype=np.int64)

    @property
    def lookahead(self) -> Lookahead:
        """The key after t sits at the centre of the next span."""
        return Lookahead(phonemes=1)

    def lookahead_for(self, options: Mapping[str, Any]) -> Lookahead | None:
        mode, lead_ms = _parse_options(options)
        return self.lookahead if mode == "lerp" else Lookahead(seconds=self.shift_s(lead_ms))

    def fidelity_ladder(self) -> tuple[Rung, ...]:
        """Interpolation first, then the damped rung that makes up its lag, then the causal
        one."""
        damped = tuple(
            Rung(
                "causal" if lead == 0 else "damped_lead",
                Lookahead(seconds=self.shift_s(lead)),
                {"mode": "damped", "lead_ms": lead},
            )
            for lead in self.leads_ms.tolist()
        )
        return (Rung("lerp", self.lookahead, {"mode": "lerp"}), *damped)

    def rung_for(self, options: Mapping[str, Any]) -> Rung | None:
        return resolved_rung(self.fidelity_ladder(), options, _parse_options)

    def kappa_for(self, lead_ms: float) -> float:
        """The fitted κ of the nearest fitted lead."""
        return float(self.kappas[int(np.argmin(np.abs(self.leads_ms - lead_ms)))])

    def shift_s(self, lead_ms: float, kappa: float | None = None) -> float:
        """How far ahead (s) a damped rung with ``lead_ms`` follows the targets: the filter's
        lag at the pooled median duration, at most the lead."""
        rate = self.kappa_for(lead_ms) if kappa is None else kappa
        return min(lead_ms / 1000.0, 2.0 * self.durations.pooled_median_s() / rate)

    def damped_targets(self, lead_ms: float, kappa: float | None = None) -> DampedTargets:
        """The damped rung's targets: each phoneme's key pose, at rate κ / median duration."""
        rate = self.kappa_for(lead_ms) if kappa is None else kappa
        omegas = rate / self.durations.expected_all_s()
        return DampedTargets(
            self.poses[self._pose_rows].astype(np.float64), omegas, self.shift_s(lead_ms, rate)
        )

    def synthesizer(self, request: SynthesisRequest) -> Synthesizer:
        mode, lead_ms = _parse_options(request.options)
        if mode == "lerp":
            return LerpSynthesizer(self, request)
        return DampedTimelineSynthesizer(self.damped_targets(lead_ms), request, self.channels)

    def render(
        self,
        spans: Sequence[PhonemeSpan],
        times: np.ndarray,
        request: SynthesisRequest,
        audio: Audio | None,
    ) -> np.ndarray:
        """One compiled call (``lerp_keys.lerp_frames``); a streaming request's spans are
        ``KeyedSpans``, which keep their keys and window from call to call."""
        keyed = spans if isinstance(spans, KeyedSpans) else KeyedSpans(spans)
        centres, phonemes = keyed.keys()
        frames, keyed.first_key = lerp_frames(
            centres,
            phonemes,
            self._pose_rows,
            self.poses,
            np.asarray(times, dtype=np.float64),
            keyed.first_key,
        )
        return frames

    def arrays(self) -> dict[str, np.ndarray]:
        return {
            "poses": self.poses,
            "lead_ms": self.leads_ms,
            "kappa": self.kappas,
            **self.durations.arrays(),
        }

    @classmethod
    def from_arrays(
        cls, manifest: ModelManifest, arrays: Mapping[str, np.ndarray], path: Path
    ) -> VisemeLerpModel:
        fields = FieldReader(str(path / MANIFEST_NAME))
        field = "hyperparameters.scheme"
        name = fields.string(fields.member(manifest.hyperparameters, "scheme", field), field)
        try:
            scheme = get_scheme(name)
        except LipstreamError as error:
            raise fields.error(field, error.message) from None
        reader = ArrayReader(arrays, str(path / ARRAYS_NAME))
        poses = reader.floats("poses", (len(scheme.classes), len(manifest.channels)))
        leads = reader.floats("lead_ms", (None,))
        kappas = reader.floats("kappa", (len(leads),), *KAPPA_RANGE)
        if len(leads) == 0 or not (np.all(leads >= 0) and np.all(leads <= MAX_LEAD_MS)):
            raise reader.error("lead_ms", f"must hold leads in [0, {MAX_LEAD_MS:g}] ms")
        return cls(manifest, poses, DurationModel.from_arrays(reader), leads, kappas)


class LerpSynthesizer(RenderingSynthesizer):
    """The ``lerp`` rung's streaming: ``render`` by the lookahead, its spans ``KeyedSpans``."""

    def __init__(self, model: VisemeLerpModel, request: SynthesisRequest) -> None:
        super().__init__(model, request)
        self.spans = KeyedSpans()


class VisemeLerpEngine(Engine):
    """Fits one mean pose per viseme class of ``scheme`` (see ``lipstream.visemes``)."""

    name = "viseme-lerp"
    model_class = VisemeLerpModel

    def __init__(self, scheme: str = "oculus15") -> None:
        self.scheme = scheme

    def fit(self, corpus: Any, *, progress: bool = False) -> VisemeLerpModel:
        scheme = get_scheme(self.scheme)
        n_channels = len(corpus.channels)
        sums = np.zeros((len(scheme.classes), n_channels))
        counts = np.zeros(len(scheme.classes))
        for utterance in corpus.utterances:
            for span in utterance.phones:
                first = int(np.ceil(span.start * corpus.fps))
                stop = min(int(np.ceil(span.end * corpus.fps)), len(utterance.frames))
                row = scheme.classes.index(scheme.viseme_of(span.phoneme))
                sums[row] += utterance.frames[first:stop].sum(axis=0)
                counts[row] += max(0, stop - first)
        poses = _mean_poses(sums, counts, scheme.classes.index(scheme.viseme_of(SILENCE)))
        durations = DurationModel.fit(utterance.phones for utterance in corpus.utterances)
        manifest = self.new_manifest(
            corpus, metrics={"frames_per_viseme": counts.astype(int).tolist()}
        )
        leads = np.array(LEADS_MS)
        model = VisemeLerpModel(manifest, poses, durations, leads, np.full(len(leads), KAPPAS[0]))
        validation = validation_utterances(corpus)
        model.kappas = np.array([_fit_kappa(model, lead, validation) for lead in LEADS_MS])
        manifest.metrics["damped_kappa"] = dict(
            zip([f"{lead:g}" for lead in LEADS_MS], model.kappas.tolist())
        )
        return model


def _fit_kappa(model: VisemeLerpModel, lead_ms: float, utterances: Sequence[Any]) -> float:
    """The κ of ``KAPPAS`` whose damped rung at ``lead_ms`` has the least squared error."""

    def synthesize(kappa: float, utterance: Any) -> np.ndarray:
        request = SynthesisRequest(fps=float(utterance.fps))
        synthesizer = DampedTimelineSynthesizer(
            model.damped_targets(lead_ms, kappa), request, model.channels
        )
        synthesizer.feed(utterance.phones)
        return synthesizer.finish()

    return best_kappa(synthesize, utterances)


def _parse_options(options: Mapping[str, Any]) -> tuple[str, float]:
    """(mode, lead_ms) of validated options; lead_ms is 0 in ``lerp`` mode."""
    mode = options.get("mode", "lerp")
    if mode not in MODES:
        raise InvalidRequestError(
            f"mode must be one of {', '.join(MODES)}, got {mode!r}", where="options.mode"
        )
    lead = lead_ms_option(options)
    if mode == "lerp" and "lead_ms" in options:
        raise InvalidRequestError("lead_ms applies to mode damped only", where="options.lead_ms")
    return str(mode), lead if mode == "damped" else 0.0


def _mean_poses(sums: np.ndarray, counts: np.ndarray, rest_row: int) -> np.ndarray:
    """Per-class means; a class never seen in training falls back to the rest pose."""
    seen = counts > 0
    if not seen.any():
        raise CorpusError("the corpus has no frames inside any phoneme span")
    poses = np.zeros_like(sums)
    poses[seen] = sums[seen] / counts[seen, None]
    fallback = poses[rest_row] if seen[rest_row] else poses[seen].mean(axis=0)
    poses[~seen] = fallback
    return poses.astype(np.float32)
