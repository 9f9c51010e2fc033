"""The trained DAM model: modes, their dominance and animemes, synthesis by Eq. 2.

Synthesis of a frame at time t inside span i: each phoneme k from i - behind to
i + ahead picks a mode (``choose_modes``: the exact search of ``selection`` over
the window of spans k - search_behind .. k + search_ahead, taking its choice at
k, compiled in ``kernels``), and the frame is the sum of D·A over those phonemes
(Eq. 2), each cut where its dominance falls below ``tol`` (see ``tails``), summed
over motion-basis components and mapped back to channels. Everything a frame reads lies
within ``tail_ahead + search_ahead`` spans after its own, which is the
lookahead. The frames are a pure function of the spans, so streaming is the
generic ``RenderingSynthesizer`` waiting for the lookahead of the request's
options; its spans are a ``DamSpans``, which keeps their arrays and chosen
modes from call to call, so each call is one compiled ``kernels.render_run``.
Below these search rungs, ``causal: true`` selects the causal rungs
(``causal``: modes committed as spans arrive, Eq. 2 over the spans begun, a
critically damped filter), which wait for ``lead_ms`` at most.

Bilabial lead: with ``bilabial_lead_s`` > 0 the search rungs render the spans with every
/p b m/ started that much earlier (``bilabial_lead``), as the model was trained; a span's
articulatory end waits for the phoneme after it, so these rungs wait one phoneme and the
lead more (``search_lookahead``), and the synthesizer hands each span to the render once its
successor has come. The causal rungs keep the acoustic spans.

Emotion: a span's emotion (its own, else the request's, else neutral) limits the
candidates to modes seen with that emotion, falling back to all the phoneme's
modes when that emotion never said it. A phoneme never trained stands in for
another (``modes.stand_ins``).

Stored ranges (checked at load, ``check_arrays``; ``bilabial_lead_s`` in [0, ``MAX_LEAD_S``],
0 when absent): σ in [``SIGMA_MIN``, 100];
context counts in [0, 2^31 − 1]; κ in [0.1, 100] (``damped_fit.KAPPA_RANGE``);
durations as in ``durations``; every other float (animeme coefficients, basis
mean) within ``MAX_MAGNITUDE``, the basis orthonormal.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ...audio import Audio
from ...bilabial_lead import MAX_LEAD_S, BilabialLead, lead_bilabials
from ...errors import InvalidRequestError
from ...model_checks import ArrayReader, FieldReader
from ...numerics.basis import MotionBasis, read_components
from ...numerics.direct_call import DirectCall
from ...phonemes import PHONEMES
from ...store import ARRAYS_NAME, MANIFEST_NAME, ModelManifest
from ...timeline import EMOTIONS, PhonemeSpan
from ..base import (
    Lookahead,
    RenderingModel,
    RenderingSynthesizer,
    Rung,
    SynthesisRequest,
    Synthesizer,
    causal_lead_ms,
    causal_rungs,
    causal_shift_s,
    final_until,
    resolved_rung,
)
from ..damped_fit import KAPPA_RANGE
from ..durations import DurationModel
from .causal import CausalSynthesizer
from .dominance import reach
from .em import SIGMA_MIN
from .kernels import Animemes, DamTables, causal_run, choose_modes, render_run, search_tables
from .modes import PHONEME_INDEX, SILENCE_INDEX, emotion_index
from .selection import Costs, Layer, end_derivatives
from .spans import DamSpans

OPTION_LIMIT = 16
NUMBER_FIELDS = (  # name, low, high, low excluded
    ("eps", 0.0, 1.0, False),
    ("tol", 0.0, 0.5, True),
    ("alpha", 0.0, 1e6, True),
    ("w_context", 0.0, 1e9, False),
    ("w_smooth", 0.0, 1e9, False),
)


class DamModel(RenderingModel):
    """The motion basis (``basis_mean``, ``basis_components``), modes grouped by phoneme
    (``mode_offsets``), ``sigma`` (modes,), ``coefficients`` (modes, M+1, components),
    context counts and ``stand_in``; ``tail`` phonemes each side and ``reference_duration``
    in the manifest's extra."""

    engine = "dam"
    fixed_degree: int | None = None
    option_names = ("search_ahead", "tail_ahead", "causal", "lead_ms")

    def __init__(self, manifest: ModelManifest, arrays: Mapping[str, np.ndarray]) -> None:
        super().__init__(manifest)
        hyper = manifest.hyperparameters
        self.stored = {name: np.array(value) for name, value in arrays.items()}
        self.basis = MotionBasis(self.stored["basis_mean"], self.stored["basis_components"])
        self.sigma = self.stored["sigma"]
        self.coefficients = self.stored["coefficients"]
        self.offsets = self.stored["mode_offsets"]
        self.stand_in = self.stored["stand_in"]
        self.count_emotion = self.stored["count_emotion"]
        self.eps = float(hyper["eps"])
        self.reach = reach(self.sigma, self.eps, float(hyper["tol"]))
        self.tail = int(manifest.extra["tail"])
        self.search_behind = int(hyper["search_behind"])
        self.search_ahead = int(hyper["search_ahead"])
        self.bilabial_lead_s = float(hyper.get("bilabial_lead_s", 0.0))
        """How far (s) /p b m/ start before their acoustic spans on the search rungs (0 in a
        model saved before the lead existed)."""
        self.durations = DurationModel(
            self.stored["duration_count"],
            self.stored["duration_log_mean"],
            self.stored["duration_log_std"],
        )
        self.causal_kappa = float(self.stored["causal_kappa"][0])
        self.span_rates = 1.0 / self.durations.expected_all_s()
        """1 / the median duration (s) of each phoneme: a causal rung's ω over κ."""
        self.costs = Costs(
            previous=self.stored["count_previous"],
            following=self.stored["count_following"],
            emotion=self.count_emotion,
            starts=end_derivatives(self.coefficients, 0.0),
            ends=end_derivatives(self.coefficients, 1.0),
            reference_duration=float(manifest.extra["reference_duration"]),
            alpha=float(hyper["alpha"]),
            w_context=float(hyper["w_context"]),
            w_smooth=float(hyper["w_smooth"]),
        )
        self.tables = DamTables(
            search_tables(self.offsets, self.stand_in, self.costs),
            Animemes(
                _float64(self.sigma), _float64(self.reach), self.eps, _float64(self.coefficients)
            ),
            _float64(self.basis.components),
            _float64(self.basis.mean),
            self.tail,
            self.search_behind,
            self.causal_kappa,
        )
        """The arrays every compiled call takes, in the groups its kernels read."""
        # Every request's streamed calls share one DirectCall per kernel: the argument types
        # are the model's and the fixed ones of the requests' buffers, bound by the first.
        self.render_call = DirectCall(render_run)
        self.causal_call = DirectCall(causal_run)

    # -- options, lookahead, ladder -------------------------------------------------------

    def resolve(self, options: Mapping[str, Any]) -> tuple[int, int] | float:
        """(search_ahead, tail_ahead) of ``options``, defaults filled in; with ``causal: true``
        the lead (ms) instead, which ignores the other two (a server merges a rung's options
        over the client's)."""
        lead = causal_lead_ms(options)
        if lead is not None:
            return lead
        values = []
        for name, default in (("search_ahead", self.search_ahead), ("tail_ahead", self.tail)):
            value = options.get(name, default)
            if isinstance(value, bool) or not isinstance(value, int):
                raise InvalidRequestError(
                    f"{name} must be an integer in [0, {OPTION_LIMIT}], got {value!r}",
                    where=f"options.{name}",
                )
            if not 0 <= value <= OPTION_LIMIT:
                raise InvalidRequestError(
                    f"{name} must be an integer in [0, {OPTION_LIMIT}], got {value!r}",
                    where=f"options.{name}",
                )
            values.append(value)
        return values[0], values[1]

    def shift_s(self, lead_ms: float) -> float:
        """How far ahead (s) a causal rung with ``lead_ms`` follows its raw curve: the filter's
        lag at the pooled median duration, at most the lead."""
        return causal_shift_s(lead_ms, self.durations.pooled_median_s(), self.causal_kappa)

    def search_lookahead(self, search: int, tail: int) -> Lookahead:
        """The wait of a search rung: ``search`` + ``tail`` phonemes. With a bilabial lead one
        more, and the lead: a span's articulatory end moves with the phoneme after it, and
        the frames up to the lead before a bilabial's onset are the bilabial's."""
        if self.bilabial_lead_s <= 0.0:
            return Lookahead(phonemes=search + tail)
        return Lookahead(seconds=self.bilabial_lead_s, phonemes=search + tail + 1)

    @property
    def lookahead(self) -> Lookahead:
        return self.search_lookahead(self.search_ahead, self.tail)

    def lookahead_for(self, options: Mapping[str, Any]) -> Lookahead | None:
        resolved = self.resolve(options)
        if isinstance(resolved, float):
            return Lookahead(seconds=self.shift_s(resolved))
        return self.search_lookahead(*resolved)

    def fidelity_ladder(self) -> tuple[Rung, ...]:
        """Mode searches looking ``search_ahead`` phonemes ahead, then fewer, then none; the
        tails stay whole on these rungs (cutting them costs far more than 1 % of a channel's
        range, see docs/explanation/engines/dam.md). Below them the causal rungs (``causal``): one
        following its curve ``base.CAUSAL_LEAD_MS`` ahead, then the causal floor."""
        rungs = []
        for search in range(self.search_ahead, -1, -1):
            name = "full" if search == self.search_ahead else f"search-{search}"
            options = {"search_ahead": search, "tail_ahead": self.tail}
            rungs.append(Rung(name, self.search_lookahead(search, self.tail), options))
        return (*rungs, *causal_rungs(self.shift_s))

    def rung_for(self, options: Mapping[str, Any]) -> Rung | None:
        return resolved_rung(self.fidelity_ladder(), options, self.resolve)

    def synthesizer(self, request: SynthesisRequest) -> Synthesizer:
        resolved = self.resolve(request.options)
        if isinstance(resolved, float):
            return CausalSynthesizer(self, request, self.shift_s(resolved))
        return DamSynthesizer(self, request)

    # -- synthesis ------------------------------------------------------------------------

    def layer(
        self, spans: Sequence[PhonemeSpan], index: int, last: int, request: SynthesisRequest
    ) -> Layer:
        """Layer ``index`` of a window ending at span ``last``."""
        span = spans[index]
        phoneme = int(self.stand_in[PHONEME_INDEX[span.phoneme]])
        candidates = np.arange(self.offsets[phoneme], self.offsets[phoneme + 1])
        emotion = emotion_index(request, span)
        said = candidates[self.count_emotion[candidates, emotion] > 0]
        if len(said):
            candidates = said
        previous = PHONEME_INDEX[spans[index - 1].phoneme] if index > 0 else SILENCE_INDEX
        if index + 1 > last:
            following = -1
        elif index + 1 < len(spans):
            following = PHONEME_INDEX[spans[index + 1].phoneme]
        else:
            following = SILENCE_INDEX
        return Layer(candidates, span.end - span.start, previous, following, emotion)

    def choose_modes(
        self,
        spans: Sequence[PhonemeSpan],
        first: int,
        last: int,
        ahead: int,
        request: SynthesisRequest,
    ) -> np.ndarray:
        """The modes of spans ``first`` .. ``last``, by the compiled search (``kernels``): each
        the choice at its span of the exact search over spans k - search_behind .. k + ``ahead``
        (those that exist); ``tests/lipstream/engines/dam/reference.py`` runs it in numpy."""
        low = max(0, first - self.search_behind)
        high = min(len(spans) - 1, last + ahead)
        window = spans[low : high + 1]
        phonemes = [PHONEME_INDEX[span.phoneme] for span in window]
        before = PHONEME_INDEX[spans[low - 1].phoneme] if low > 0 else SILENCE_INDEX
        after = PHONEME_INDEX[spans[high + 1].phoneme] if high + 1 < len(spans) else SILENCE_INDEX
        emotion = np.array([emotion_index(request, span) for span in window], dtype=np.int64)
        phoneme = np.array(phonemes, dtype=np.int64)
        return np.asarray(
            choose_modes(
                phoneme * self.tables.search.set_start.shape[1] + emotion,
                np.array([before, *phonemes[:-1]], dtype=np.int64),
                np.array([*phonemes[1:], after], dtype=np.int64),
                emotion,
                np.array([span.end - span.start for span in window]),
                first - low,
                last - low,
                self.search_behind,
                ahead,
                self.tables.search,
            )
        )

    def render(
        self,
        spans: Sequence[PhonemeSpan],
        times: np.ndarray,
        request: SynthesisRequest,
        audio: Audio | None,
    ) -> np.ndarray:
        """One compiled call (``kernels.render_run``) on the bilabials' articulatory spans
        (``bilabial_lead``); a streaming request's spans are its ``DamSpans``, led already,
        which keep their arrays and chosen modes between calls."""
        if isinstance(spans, DamSpans) and spans.request is request:
            tracked = spans
        else:
            resolved = self.resolve(request.options)
            assert not isinstance(resolved, float), "causal rungs stream with CausalSynthesizer"
            if self.bilabial_lead_s > 0.0:
                spans = lead_bilabials(spans, self.bilabial_lead_s)
            tracked = DamSpans(request, resolved, spans)
        search, ahead = tracked.resolved
        request.guard.check()
        frames: np.ndarray
        frames, tracked.owner = self.render_call(
            np.ascontiguousarray(times, dtype=np.float64),
            tracked.owner,
            tracked.arrays(),
            tracked.rows,
            search,
            ahead,
            self.tables,
        )
        return frames

    # -- store ----------------------------------------------------------------------------

    def arrays(self) -> dict[str, np.ndarray]:
        return dict(self.stored)

    @classmethod
    def from_arrays(
        cls, manifest: ModelManifest, arrays: Mapping[str, np.ndarray], path: Path
    ) -> DamModel:
        fields = FieldReader(str(path / MANIFEST_NAME))
        hyper = fields.mapping(manifest.hyperparameters, "hyperparameters")
        extra = fields.mapping(manifest.extra, "extra")

        def member(mapping: Mapping[str, Any], prefix: str, name: str) -> tuple[Any, str]:
            field = f"{prefix}.{name}"
            return fields.member(mapping, name, field), field

        degree = cls.fixed_degree
        if degree is None:
            degree = fields.integer(*member(hyper, "hyperparameters", "degree"), 0, 12)
        for name, low, high, above in NUMBER_FIELDS:
            fields.number(*member(hyper, "hyperparameters", name), low, high, above=above)
        for name in ("search_behind", "search_ahead"):
            fields.integer(*member(hyper, "hyperparameters", name), 0, OPTION_LIMIT)
        fields.integer(*member(extra, "extra", "tail"), 0, OPTION_LIMIT)
        fields.number(*member(extra, "extra", "reference_duration"), 0.0, 60.0, above=True)
        if "bilabial_lead_s" in hyper:  # absent from models saved before it: no lead
            fields.number(
                hyper["bilabial_lead_s"], "hyperparameters.bilabial_lead_s", 0.0, MAX_LEAD_S
            )
        reader = ArrayReader(arrays, str(path / ARRAYS_NAME))
        return cls(manifest, check_arrays(reader, degree, len(manifest.channels)))


def _float64(values: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(values, dtype=np.float64)


MAX_COUNT = 2**31 - 1
"""The most training spans a mode's context count may record (a kernel sums a row of them)."""


def check_arrays(reader: ArrayReader, degree: int, n_channels: int) -> dict[str, np.ndarray]:
    """Every array read with kind, shape and range checked; the modes grouped by phoneme."""
    n_phonemes = len(PHONEMES)
    mean = reader.floats("basis_mean", (n_channels,))
    components = read_components(reader, "basis_components", n_channels)
    phoneme = reader.integers("mode_phoneme", (None,), 0, n_phonemes)
    n_modes = len(phoneme)
    if n_modes == 0:
        raise reader.error("mode_phoneme", "is empty: a model needs at least one mode")
    offsets = reader.offsets("mode_offsets", n_phonemes, n_modes, nonempty=False)
    expected = np.repeat(np.arange(n_phonemes), np.diff(offsets))
    if not np.array_equal(phoneme, expected):
        raise reader.error(
            "mode_phoneme", "does not group the modes by phoneme as mode_offsets says"
        )
    stand_in = reader.integers("stand_in", (n_phonemes,), 0, n_phonemes)
    if (np.diff(offsets)[stand_in] == 0).any():
        raise reader.error("stand_in", "names a phoneme without modes")
    sigma = reader.floats("sigma", (n_modes,))
    if (sigma < SIGMA_MIN).any() or (sigma > 100.0).any():
        raise reader.error("sigma", f"must lie in [{SIGMA_MIN}, 100]")
    result = {
        "mode_phoneme": phoneme,
        "mode_offsets": offsets,
        "stand_in": stand_in,
        "sigma": sigma,
        "coefficients": reader.floats("coefficients", (n_modes, degree + 1, len(components))),
        "basis_mean": mean,
        "basis_components": components,
    }
    for name, width in (
        ("count_previous", n_phonemes),
        ("count_following", n_phonemes),
        ("count_emotion", len(EMOTIONS)),
    ):
        result[name] = reader.integers(name, (n_modes, width), 0, MAX_COUNT + 1)
    result.update(DurationModel.from_arrays(reader).arrays())
    result["causal_kappa"] = reader.floats("causal_kappa", (1,), *KAPPA_RANGE)
    return result


class DamSynthesizer(RenderingSynthesizer):
    """The generic rendering synthesizer, waiting for the lookahead of the request's options
    (resolved once); it renders ``DamSpans``. Without a bilabial lead those are the spans
    fed; with one, their articulatory spans (``bilabial_lead.BilabialLead``), each handed
    on once the span after it has come, the last at ``finish``."""

    def __init__(self, model: DamModel, request: SynthesisRequest) -> None:
        super().__init__(model, request)
        resolved = model.resolve(request.options)
        assert not isinstance(resolved, float), "causal rungs stream with CausalSynthesizer"
        self.led = DamSpans(request, resolved)
        self.leader: BilabialLead | None = None
        if model.bilabial_lead_s > 0.0:
            self.leader = BilabialLead(model.bilabial_lead_s)
        else:
            self.spans = self.led
        self._lookahead = model.search_lookahead(*resolved)

    def _accepted(self, span: PhonemeSpan, sent: int | None) -> None:
        if self.leader is not None and (final := self.leader.push(span)) is not None:
            self.led.append(final)

    def rendered_spans(self) -> Sequence[PhonemeSpan]:
        return self.led

    def final_until(self) -> float:
        return final_until(self.spans, self._lookahead)

    def finish(self) -> np.ndarray:
        if self.leader is not None and (last := self.leader.close()) is not None:
            self.led.append(last)
        return super().finish()


class CohenMassaroModel(DamModel):
    """The same model with constant animemes (M = 0)."""

    engine = "cohen-massaro"
    fixed_degree = 0
