"""The engine contract: how engines are trained, stored and streamed.

An ``Engine`` holds hyperparameters and ``fit``s a corpus into a ``Model``.
A ``Model`` is the resident, read-only trained state: it saves to and loads
from a model directory (``lipstream.store``) and ``start``s one
``Synthesizer`` per request.

Streaming rule: a synthesizer emits the frame for time t once the input
covers t plus the model's declared ``Lookahead``. Feeding the input in any
chunking yields the same frames as one offline call, because every frame is
computed from the spans known when it becomes final, and those spans never
change afterwards. Frame i is at time i / fps seconds; gaps in the input are
silence, spoken with the emotion of the span after the gap.

Fidelity: ``Model.fidelity_ladder`` lists the ``Rung``s an engine serves at,
best first, each with the engine options that select it and the
``Lookahead`` those options need; a server takes the best rung that fits a
latency budget. The last rung is causal: its lookahead is zero (no
phonemes, no seconds, at most a few milliseconds of audio window), so the
frame for t is final once the input covers t. Rungs between may wait a fixed
time (a lead) rather than whole phonemes.

Options: a model declares the engine options it takes in ``option_names``;
``start`` refuses any other name through ``check_options`` (one coded
``invalid_request`` error, listing the known names, for every engine) before
the engine reads their values.

Cost and stopping: ``Model.call_cost(options, measured)`` is the engine's
estimate of what one streaming call costs (per phoneme it decides, per frame
it may emit) for a request with those options: calibration's measurement when
the options select a rung, else the engine's own worst case (unbounded unless
the engine knows better). A server runs a call off its event loop when the
estimate is large. ``SynthesisRequest.guard`` (``work.WorkGuard``) is the
request's cancellation and CPU-budget token: a synthesizer checks it between
the steps of its long loops, and stops there.

Emotion: ``SynthesisRequest.emotion`` is the request's; a span's own
``PhonemeSpan.emotion`` overrides it for that span (``emotion_of``). A
request that names none is spoken with the model's ``default_emotion``
(``start`` fills it in): the manifest's ``extra.default_emotion``, else
``neutral``, so a search never mixes the moods of every recording. Engines
that model emotion honour both (anime-graph searches each run of equal
emotion among that emotion's recordings); the ``viseme-lerp`` baseline has
one key pose per viseme and ignores emotion altogether.
"""

from __future__ import annotations

import inspect
import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, ClassVar, Protocol, Self, SupportsIndex, TypeVar, overload

import numpy as np

from .._version import __version__
from ..audio import Audio
from ..errors import InvalidRequestError, ModelStoreError
from ..model_checks import field_error
from ..phonemes import PHONEMES, SILENCE
from ..store import (
    MANIFEST_NAME,
    ModelManifest,
    load_arrays,
    read_manifest,
    save_model_dir,
)
from ..store import (
    MAX_FPS as MAX_FPS,  # re-exported: the request fps bound
)
from ..timeline import (
    EMOTIONS,
    NormalizedSpans,
    PhonemeSpan,
    SpanLike,
    coerce_spans,
    follow_checked,
)
from .work import WorkGuard

MIN_FPS = 1.0  # lowest request frame rate, Hz (the highest, MAX_FPS, is the store's)
DEFAULT_EMOTION = "neutral"
DEFAULT_EMOTION_KEY = "default_emotion"
AUDIO_ONLY_UNSUPPORTED = "audio_only_unsupported"  # the protocol's error code
_EPS = 1e-9

ModelT = TypeVar("ModelT", bound="Model")


@dataclass(frozen=True)
class Lookahead:
    """Input a frame waits for.

    The frame at time t is final once the input covers ``t + seconds`` and
    holds at least ``phonemes`` whole spans after the span containing
    ``t + seconds``. With a phoneme count the wait is bounded by phoneme
    durations, so servers budget it with a maximum phoneme duration. A request
    that carries audio also waits until the audio reaches ``audio_seconds``
    past the end of that input (feature windows centred near the end).
    """

    seconds: float = 0.0
    phonemes: int = 0
    audio_seconds: float = 0.0


@dataclass(frozen=True)
class Rung:
    """One fidelity level an engine serves at, best first in ``Model.fidelity_ladder``.

    ``options`` are the engine options that select the rung; ``lookahead`` is
    the input its frames wait for.
    """

    name: str
    lookahead: Lookahead
    options: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class CallCost:
    """Estimated milliseconds of one streaming call: per phoneme it decides and per frame it
    may emit (``math.inf``: no bound is known)."""

    per_phoneme_ms: float
    per_frame_ms: float

    def ms(self, phonemes: int, frames: int) -> float:
        """The estimate for a call deciding ``phonemes`` phonemes and emitting ``frames``."""
        total = 0.0
        if phonemes > 0:
            total += self.per_phoneme_ms * phonemes
        if frames > 0:
            total += self.per_frame_ms * frames
        return total


UNBOUNDED_COST = CallCost(math.inf, math.inf)


@dataclass(frozen=True)
class SynthesisRequest:
    """Per-request settings: output ``fps`` (Hz), ``emotion`` (of every span that names
    none), engine options, and the ``guard`` that stops the request's work."""

    fps: float = 60.0
    emotion: str | None = None
    options: Mapping[str, Any] = field(default_factory=dict)
    guard: WorkGuard = field(default_factory=WorkGuard, compare=False, repr=False)

    def __post_init__(self) -> None:
        fps = self.fps
        if isinstance(fps, bool) or not (
            isinstance(fps, (int, float)) and MIN_FPS <= fps <= MAX_FPS
        ):
            raise InvalidRequestError(
                f"fps must be in [{MIN_FPS:g}, {MAX_FPS:g}], got {fps!r}", where="fps"
            )
        if self.emotion is not None and self.emotion not in EMOTIONS:
            raise InvalidRequestError(
                f"emotion must be one of {EMOTIONS}, got {self.emotion!r}", where="emotion"
            )
        # one type whatever the client sent (30 or 30.0): compiled kernels take it as is
        object.__setattr__(self, "fps", float(fps))

    def emotion_of(self, span: PhonemeSpan) -> str | None:
        """The emotion ``span`` is spoken with: its own, else the request's."""
        return span.emotion if span.emotion is not None else self.emotion


@dataclass(frozen=True)
class SynthesisResult:
    """Offline output: ``frames`` float32 (n_frames, n_channels) at ``fps``, frame i at i/fps s.

    Unpacks as ``frames, channels, fps = model.synthesize(...)`` and is indexed the same
    way (``result[0]`` is ``frames``, ``len(result) == 3``). Not a NamedTuple: ``stats``
    (the engine's counters) would then unpack as a fourth value.
    """

    frames: np.ndarray
    channels: tuple[str, ...]
    fps: float
    stats: dict[str, Any] = field(default_factory=dict)

    def _unpacked(self) -> tuple[np.ndarray, tuple[str, ...], float]:
        return (self.frames, self.channels, self.fps)

    def __iter__(self) -> Iterator[Any]:
        return iter(self._unpacked())

    def __len__(self) -> int:
        return 3

    @overload
    def __getitem__(self, index: SupportsIndex) -> Any: ...

    @overload
    def __getitem__(self, index: slice) -> tuple[Any, ...]: ...

    def __getitem__(self, index: SupportsIndex | slice) -> Any:
        return self._unpacked()[index]


def frame_count(end_s: float, fps: float) -> int:
    """Frames i = 0.. with i / fps <= end_s."""
    return math.floor(end_s * fps + _EPS) + 1


def frames_before(t_s: float, fps: float) -> int:
    """Frames i = 0.. with i / fps < t_s."""
    return max(0, math.ceil(t_s * fps - _EPS))


def fill_gaps(spans: Sequence[PhonemeSpan], start: float = 0.0) -> list[PhonemeSpan]:
    """Make the timeline contiguous from ``start``: every gap becomes a silence span with
    the emotion of the span after it (the pause leads into that span)."""
    filled: list[PhonemeSpan] = []
    cursor = start
    for span in spans:
        if span.start > cursor + _EPS:
            filled.append(PhonemeSpan(SILENCE, cursor, span.start, span.emotion))
        filled.append(span)
        cursor = span.end
    return filled


def final_until(spans: Sequence[PhonemeSpan], lookahead: Lookahead) -> float:
    """Time (s) before which every frame is final, for contiguous ``spans`` received so far."""
    index = len(spans) - 1 - lookahead.phonemes
    if index < 0:
        return 0.0
    return spans[index].end - lookahead.seconds


class Synthesizer(ABC):
    """One request's streaming state. Not thread-safe; one per request."""

    stats: dict[str, Any]
    finished: bool

    def feed(self, spans: Iterable[SpanLike], audio: Audio | None = None) -> None:
        """Append phoneme spans (absolute seconds, in order) and optional audio.

        The one entry of spans, from the server and from the Python API alike: each is
        checked and its label normalized here, once (``timeline.coerce_spans``; spans an
        edge normalized already come as ``NormalizedSpans`` and are only checked to follow
        on, ``timeline.follow_checked``), and the engine ``take``s them as they are."""
        if self.finished:
            raise InvalidRequestError("input fed after finish()", code="request_finished")
        after, first_index = self.span_position()
        if type(spans) is NormalizedSpans:
            self.take(follow_checked(spans, after, first_index), audio)
        else:
            self.take(coerce_spans(spans, after=after, first_index=first_index), audio)

    @abstractmethod
    def span_position(self) -> tuple[float, int]:
        """The end (s) of the spans taken so far, and the index that error locations give
        the next span fed."""

    @abstractmethod
    def take(self, spans: Sequence[PhonemeSpan], audio: Audio | None) -> None:
        """Append ``spans``, checked, with canonical labels and following the input so far,
        and ``audio``."""

    @abstractmethod
    def frames(self) -> np.ndarray:
        """Frames that became final since the last call, float32 (n, n_channels)."""

    @abstractmethod
    def finish(self) -> np.ndarray:
        """Declare the input complete and return every frame not yet returned."""

    @property
    def held_input_bytes(self) -> int:
        """Bytes this request holds of its audio input (samples and the features made of
        them), which the server counts against its memory ceiling as input arrives."""
        return 0

    def check_more_phonemes(self, count: int) -> None:
        """Raise the engine's error (``LipstreamError``) if this request could not take
        ``count`` more phonemes: an engine whose work grows too fast with a request's length
        caps it, and the server asks as soon as it receives phonemes, before any search.
        By default there is no cap."""
        return None

    def held_input_bytes_after(self, n_samples: int, sample_rate: int) -> int:
        """A bound on ``held_input_bytes`` while this request takes in ``n_samples`` more
        samples of audio at ``sample_rate`` Hz (0 when the engine does not keep audio)."""
        return 0


class Model(ABC):
    """A trained, read-only model. Subclasses define how a request streams
    (``synthesizer``) and the array round trip; a model that renders frames at given times
    from the spans is a ``RenderingModel``."""

    engine: ClassVar[str]
    uses_audio: bool = False
    """Whether a request's audio reaches the synthesizer (a model may decide at load)."""
    option_names: ClassVar[tuple[str, ...]] = ()

    def __init__(self, manifest: ModelManifest) -> None:
        self.manifest = manifest

    @property
    def channels(self) -> tuple[str, ...]:
        return tuple(self.manifest.channels)

    @property
    def name(self) -> str:
        return self.manifest.name

    @abstractmethod
    def arrays(self) -> dict[str, np.ndarray]:
        """The arrays that ``save`` writes next to the manifest."""

    @classmethod
    @abstractmethod
    def from_arrays(
        cls: type[ModelT], manifest: ModelManifest, arrays: Mapping[str, np.ndarray], path: Path
    ) -> ModelT:
        """Rebuild a model from its manifest and (memory-mapped) arrays."""

    @property
    def accepts_audio_only(self) -> bool:
        """Whether audio alone (no phonemes) can drive the model; engines that can say so."""
        return False

    @property
    def lookahead(self) -> Lookahead:
        """The input a frame waits for (see ``Lookahead``); engines override it."""
        return Lookahead()

    def lookahead_for(self, options: Mapping[str, Any]) -> Lookahead | None:
        """The lookahead of a request with these engine ``options`` (None: a frame may wait
        for the end of the input); engines whose options change it override this."""
        return self.lookahead

    def fidelity_ladder(self) -> tuple[Rung, ...]:
        """Fidelity levels, best first; a server picks the best that fits a latency budget.

        Each rung's ``options`` must pin every option its ``lookahead`` depends on, since a
        server lets them override the client's; rungs further down should wait less."""
        return (Rung("default", self.lookahead),)

    def rung_for(self, options: Mapping[str, Any]) -> Rung | None:
        """The rung of ``fidelity_ladder`` that these engine ``options`` select exactly, None
        when they leave the ladder; engines whose options have defaults override it to
        compare the options they resolve to (``resolved_rung``)."""
        return resolved_rung(self.fidelity_ladder(), options, dict)

    def call_cost(self, options: Mapping[str, Any], measured: Mapping[str, CallCost]) -> CallCost:
        """The estimated cost of one streaming call of a request with these ``options``.

        ``measured`` holds calibration's cost of each rung, by name: options that select a
        rung (``rung_for``) cost what it measured. Other options cost the engine's own worst
        case, unbounded here: no measurement vouches for them. Engines that can bound the
        work of options outside their ladder override this."""
        rung = self.rung_for(options)
        if rung is not None and rung.name in measured:
            return measured[rung.name]
        return UNBOUNDED_COST

    @property
    def default_emotion(self) -> str:
        """The emotion of a request that names none: the manifest's ``extra.default_emotion``,
        else ``neutral``."""
        value = self.manifest.extra.get(DEFAULT_EMOTION_KEY, DEFAULT_EMOTION)
        return str(value) if value in EMOTIONS else DEFAULT_EMOTION  # ``load`` checks it

    def start(self, request: SynthesisRequest | None = None, **settings: Any) -> Synthesizer:
        """A streaming synthesizer; pass a ``SynthesisRequest`` or its fields. A request
        without an emotion gets ``default_emotion``.

        InvalidRequestError if the request names an option outside ``option_names``."""
        if request is None:
            request = make_request(**settings)
        if request.emotion is None:
            request = replace(request, emotion=self.default_emotion)
        check_options(self.engine, self.option_names, request.options)
        return self.synthesizer(request)

    @abstractmethod
    def synthesizer(self, request: SynthesisRequest) -> Synthesizer:
        """The synthesizer of a request whose option names are checked."""

    def synthesize(
        self,
        spans: Iterable[SpanLike],
        fps: float = 60.0,
        audio: Audio | None = None,
        emotion: str | None = None,
        **engine_options: Any,
    ) -> SynthesisResult:
        """Offline synthesis of a whole utterance; with no spans, of ``audio`` alone (engines
        that can, see ``accepts_audio_only``; the others raise ``audio_only_unsupported``)."""
        request = SynthesisRequest(fps=fps, emotion=emotion, options=engine_options)
        spans = list(spans)
        if not spans and audio is not None and not self.accepts_audio_only:
            raise InvalidRequestError(
                f"model {self.name!r} of engine {self.engine} cannot be driven by audio alone; "
                "pass phoneme spans with the audio",
                where="spans",
                code=AUDIO_ONLY_UNSUPPORTED,
            )
        synthesizer = self.start(request)
        synthesizer.feed(spans, audio)
        frames = synthesizer.finish()
        return SynthesisResult(frames, self.channels, float(fps), dict(synthesizer.stats))

    def save(self, path: str | Path) -> None:
        save_model_dir(Path(path), self.manifest, self.arrays())

    @classmethod
    def load(cls, path: str | Path) -> Self:
        directory = Path(path)
        manifest = read_manifest(directory)
        if manifest.engine != cls.engine:
            raise ModelStoreError(
                f"model was trained by engine {manifest.engine!r}, not {cls.engine!r}",
                where=str(directory),
                code="model_engine_mismatch",
            )
        if manifest.phoneme_set != list(PHONEMES):
            raise field_error(
                str(directory / MANIFEST_NAME),
                "phoneme_set",
                "differs from this lipstream's phoneme set (lipstream.phonemes.PHONEMES), "
                "which every engine's stored labels index; retrain the model",
            )
        emotion = manifest.extra.get(DEFAULT_EMOTION_KEY, DEFAULT_EMOTION)
        if emotion not in EMOTIONS:
            raise field_error(
                str(directory / MANIFEST_NAME),
                f"extra.{DEFAULT_EMOTION_KEY}",
                f"must be one of {', '.join(EMOTIONS)}, got {emotion!r}",
            )
        arrays = load_arrays(directory, manifest.array_sizes)
        return cls.from_arrays(manifest, arrays, directory)


def resolved_rung(
    ladder: Iterable[Rung],
    options: Mapping[str, Any],
    resolve: Callable[[Mapping[str, Any]], object],
) -> Rung | None:
    """The first rung of ``ladder`` whose options ``resolve`` to what ``options`` resolve to
    (an engine's option parser, defaults filled in), None when none does; ``options`` are
    resolved first, so bad ones raise the parser's error."""
    resolved = resolve(options)
    return next((rung for rung in ladder if resolve(rung.options) == resolved), None)


MAX_LEAD_MS = 1000.0
CAUSAL_LEAD_MS = 120.0
"""The lead of the ``causal_lead`` rung of the engines whose causal rungs follow a raw curve
ahead of time."""


def lead_ms_option(options: Mapping[str, Any]) -> float:
    """The ``lead_ms`` option (0 when absent): a number of milliseconds in [0,
    ``MAX_LEAD_MS``], else ``InvalidRequestError`` at ``options.lead_ms``."""
    lead = options.get("lead_ms", 0.0)
    if isinstance(lead, bool) or not isinstance(lead, (int, float)) or not 0 <= lead <= MAX_LEAD_MS:
        raise InvalidRequestError(
            f"lead_ms must be a number of milliseconds in [0, {MAX_LEAD_MS:g}], got {lead!r}",
            where="options.lead_ms",
        )
    return float(lead)


def causal_lead_ms(options: Mapping[str, Any]) -> float | None:
    """The lead (ms) of options asking for a causal rung (``causal: true``, ``lead_ms`` in
    [0, ``MAX_LEAD_MS``], 0 by default), None without ``causal``; ``lead_ms`` without it is
    refused, as is any other type (``InvalidRequestError`` naming the option)."""
    causal = options.get("causal", False)
    if not isinstance(causal, bool):
        raise InvalidRequestError(
            f"causal must be true or false, got {causal!r}", where="options.causal"
        )
    lead = lead_ms_option(options)
    if causal:
        return lead
    if "lead_ms" in options:
        raise InvalidRequestError("lead_ms applies with causal: true only", where="options.lead_ms")
    return None


def causal_shift_s(lead_ms: float, pooled_median_s: float, kappa: float) -> float:
    """How far ahead (s) a causal rung with ``lead_ms`` follows its raw curve through a
    critically damped filter at ω = ``kappa`` / duration: the filter's lag 2 / ω at the
    pooled median phoneme duration, at most the lead."""
    return min(lead_ms / 1000.0, 2.0 * pooled_median_s / kappa)


def causal_rungs(
    shift_s: Callable[[float], float],
    leads_ms: Iterable[float] = (CAUSAL_LEAD_MS, 0.0),
    pinned: Mapping[str, Any] | None = None,
) -> tuple[Rung, ...]:
    """The causal rungs at the foot of a ladder, one per lead of ``leads_ms`` (a lead of 0 is
    ``causal``, the floor; any other ``causal_lead``), each waiting ``shift_s(lead)`` seconds;
    their options are ``pinned`` (options the engine's causal search also fixes) followed by
    ``causal: true`` and ``lead_ms``."""
    return tuple(
        Rung(
            "causal" if lead == 0 else "causal_lead",
            Lookahead(seconds=shift_s(lead)),
            {**(pinned or {}), "causal": True, "lead_ms": lead},
        )
        for lead in leads_ms
    )


def check_options(engine: str, known: Sequence[str], options: Mapping[str, Any]) -> None:
    """InvalidRequestError (``invalid_request``, at ``options.<name>``) naming every option in
    ``options`` that ``engine`` does not know, and listing the ones it does."""
    unknown = sorted(str(name) for name in options if name not in known)
    if unknown:
        raise InvalidRequestError(
            f"unknown option(s) {', '.join(unknown)} for engine {engine}; "
            f"known options: {', '.join(known) or 'none'}",
            where=f"options.{unknown[0]}",
        )


def make_request(fps: float = 60.0, emotion: str | None = None, **options: Any) -> SynthesisRequest:
    return SynthesisRequest(fps=fps, emotion=emotion, options=options)


class RenderingModel(Model):
    """A model whose frames are a function of the spans (and audio) at given times, final
    once the input covers each time plus the ``lookahead``: it streams through
    ``RenderingSynthesizer``."""

    @abstractmethod
    def render(
        self,
        spans: Sequence[PhonemeSpan],
        times: np.ndarray,
        request: SynthesisRequest,
        audio: Audio | None,
    ) -> np.ndarray:
        """Frames at ``times`` (s, shape (n,)) as float32 (n, n_channels).

        ``spans`` is contiguous from 0. Every time passed is final under the
        model's ``lookahead``, so the result may only depend on spans that
        end before ``t`` plus that lookahead.
        """

    def synthesizer(self, request: SynthesisRequest) -> Synthesizer:
        return RenderingSynthesizer(self, request)


class Engine(ABC):
    """A trainer: hyperparameters in ``__init__``, ``fit`` returns a ``Model``.

    An engine holds only its hyperparameters, each stored under the name of its
    constructor argument; ``fit`` leaves the engine as it was, and everything learned
    lives in the returned ``Model``."""

    name: ClassVar[str]
    model_class: ClassVar[type[Model]]

    @abstractmethod
    def fit(self, corpus: Any, *, progress: bool = False) -> Model:
        """Train on a ``lipstream.corpus.Corpus``."""

    def new_manifest(self, corpus: Any, **fields: Any) -> ModelManifest:
        """A manifest describing a model of this engine trained on ``corpus``."""
        return ModelManifest(
            engine=self.name,
            name=corpus.name,
            channels=list(corpus.channels),
            fps=float(corpus.fps),
            phoneme_set=list(PHONEMES),
            hyperparameters=self.hyperparameters(),
            corpus_digest=corpus.digest(),
            lipstream_version=__version__,
            **fields,
        )

    @classmethod
    def hyperparameter_names(cls) -> list[str]:
        """The constructor's parameters, in order, read from its signature as scikit-learn's
        ``get_params`` reads them; TypeError for ``*args`` or ``**kwargs``, which name none."""
        if cls.__init__ is object.__init__:
            return []
        names = []
        for parameter in list(inspect.signature(cls.__init__).parameters.values())[1:]:
            if parameter.kind in (parameter.VAR_POSITIONAL, parameter.VAR_KEYWORD):
                raise TypeError(
                    f"{cls.__name__}.__init__ takes *{parameter.name}: an engine names each "
                    f"hyperparameter in its signature"
                )
            names.append(parameter.name)
        return names

    def hyperparameters(self) -> dict[str, Any]:
        """The constructor arguments, as stored in the manifest: each is kept on the engine
        under its own name, so ``type(engine)(**engine.hyperparameters())`` is the same
        engine."""
        return {name: getattr(self, name) for name in self.hyperparameter_names()}


class SpanSynthesizer(Synthesizer):
    """A synthesizer that keeps its request's spans, gaps filled with silence, and its audio
    as they are fed; ``_accepted(span, sent)`` sees each new span, with its index among the
    spans the client sent (``None`` for a silence filled into a gap). ``sent`` counts them."""

    def __init__(self) -> None:
        self.spans: list[PhonemeSpan] = []
        self.sent = 0
        self.audio: Audio | None = None
        self.emitted = 0
        self.finished = False
        self.stats = {"frames": 0}

    @property
    def covered_until(self) -> float:
        return self.spans[-1].end if self.spans else 0.0

    def span_position(self) -> tuple[float, int]:
        return self.covered_until, self.sent

    def take(self, spans: Sequence[PhonemeSpan], audio: Audio | None) -> None:
        for span in spans:
            for piece in fill_gaps([span], self.covered_until):
                self.spans.append(piece)
                self._accepted(piece, self.sent if piece is span else None)
            self.sent += 1
        if audio is not None:
            self.audio = audio if self.audio is None else self.audio.concat(audio)

    def _accepted(self, span: PhonemeSpan, sent: int | None) -> None:
        """Called with each span as it joins ``spans``; ``sent`` is its client index."""


class LookaheadSource(Protocol):
    """What a ``LookaheadSynthesizer`` reads of its model (an engine's own synthesizers say
    what more they read in a protocol that extends this one)."""

    @property
    def lookahead(self) -> Lookahead: ...
    @property
    def uses_audio(self) -> bool: ...


class LookaheadSynthesizer(SpanSynthesizer):
    """Streams a model's frames by its declared ``Lookahead``: a frame is emitted once it is
    final; subclasses make the frames (``_emit``)."""

    def __init__(self, model: LookaheadSource, request: SynthesisRequest) -> None:
        super().__init__()
        self.model = model
        self.request = request

    def final_until(self) -> float:
        """Time (s) before which every frame is final."""
        if not self.spans:
            return 0.0
        lookahead = self.model.lookahead
        limit = final_until(self.spans, lookahead)
        if self.model.uses_audio and self.audio is not None:
            limit = min(limit, self.audio.duration - lookahead.seconds)
        return limit

    @abstractmethod
    def _emit(self, stop: int) -> np.ndarray:
        """Frames ``emitted`` .. ``stop`` − 1 as float32 (n, n_channels); advances
        ``emitted``."""

    def frames(self) -> np.ndarray:
        return self._emit(frames_before(self.final_until(), self.request.fps))

    def finish(self) -> np.ndarray:
        self.finished = True
        total = frame_count(self.covered_until, self.request.fps) if self.spans else 0
        return self._emit(total)


class RenderingSynthesizer(LookaheadSynthesizer):
    """Streams a ``RenderingModel``'s ``render``."""

    model: RenderingModel

    def __init__(self, model: RenderingModel, request: SynthesisRequest) -> None:
        super().__init__(model, request)

    def rendered_spans(self) -> Sequence[PhonemeSpan]:
        """The spans ``render`` is given: those fed, unless the model renders others made from
        them (dam's articulatory spans)."""
        return self.spans

    def _emit(self, stop: int) -> np.ndarray:
        if stop <= self.emitted:
            return np.zeros((0, len(self.model.channels)), dtype=np.float32)
        self.request.guard.check()
        times = np.arange(self.emitted, stop, dtype=np.float64) / self.request.fps
        frames = np.asarray(
            self.model.render(self.rendered_spans(), times, self.request, self.audio),
            dtype=np.float32,
        )
        self.emitted = stop
        self.stats["frames"] = stop
        return frames


def shifted_frame_stop(synthesizer: SpanSynthesizer, shift_s: float, fps: float) -> int:
    """The frames final when the frame at t waits for the input to cover t + ``shift_s``: those
    with i / fps <= the input's end - ``shift_s``; the frames already emitted while no span
    has come or that is before 0."""
    reach = synthesizer.covered_until - shift_s
    if not synthesizer.spans or reach < 0.0:
        return synthesizer.emitted
    return frame_count(reach, fps)


class ShiftedSynthesizer(LookaheadSynthesizer):
    """A causal or lead rung's synthesizer: the frame at t is final once the input covers
    t + ``shift_s`` (which subclasses set); their ``_emit`` carries the filter's state."""

    shift_s: float

    def final_until(self) -> float:
        return self.covered_until - self.shift_s if self.spans else 0.0

    def frames(self) -> np.ndarray:
        return self._emit(shifted_frame_stop(self, self.shift_s, self.request.fps))
