"""The trained voice-puppetry model: the facial HMM remapped to vocal outputs.

Arrays: the motion basis (``basis_mean``, ``basis_components``, D components);
the state machine (``start`` (N,), ``transition`` (N, N)); each state's
Gaussian over [pose, velocity] (``means`` (N, 2D), ``covariances`` (N, 2D, 2D));
its phoneme and emotion categoricals (``phoneme_log_probs`` (N, phonemes),
``emotion_log_probs`` (N, emotions)); and, when the
corpus had audio, its Gaussian over speech features (``vocal_means`` (N, F),
``vocal_covariances`` (N, F, F); F = 0 without audio), with the speaker
normalization's prior (``vocal_prior_mean``, ``vocal_prior_variance`` (F,)) when it
was trained normalized. The manifest's extra holds ``hmm_fps``, ``has_audio``, the
feature analysis (``mfcc``) and the normalization's scalars (``normalization``; null,
or absent in a model saved before it: the model hears raw features). The
hyperparameter ``sample_offset`` says where in its HMM frame training sampled the face
(``engine.observations``); a model saved before it has none and was sampled at the
frame's instant, ``INSTANT_SAMPLING``. The hyperparameter ``bilabial_lead_s`` says how far
(s) every /p b m/ span started before its acoustic onset when the phoneme categoricals were
trained (``bilabial_lead``); a model saved before it has none and trained on the acoustic
spans (0).

Options: ``lag_ms`` (the Viterbi lag limit; null: unlimited), ``window_ms``
(the trajectory block; 0: a frame at a time; null: one solve at the end) and
``drive`` (``auto``, ``phonemes``, ``audio``, ``both``; see ``synthesizer``). The
ladder (``RUNGS``) runs from a half-second lag with quarter-second blocks down
to the causal rung (lag 0, a frame at a time), which also hears audio a few
frames late rather than wait for a feature window (``synthesizer``).

Bilabial lead: with ``bilabial_lead_s`` > 0 the rungs that wait for a feature window (lag
above ``NO_WAIT_BELOW_MS``, or unlimited) read each HMM frame's phoneme from the spans with
every /p b m/ started that much earlier, as the model was trained. The phoneme at t is then
final once the spans cover t + lead (a bilabial starting within the lead after t takes t),
so these rungs wait the lead more (``Plan.lead_s``); the ``causal_lead`` and ``causal``
rungs keep the acoustic spans, as does a request driven by audio alone.

Stored ranges (checked at load, ``check_arrays``; ``bilabial_lead_s`` in [0,
``MAX_LEAD_S``], 0 when absent): probabilities non-negative and
summing to 1, log-probabilities summing to 1, covariances symmetric positive
definite, and every float within ``MAX_MAGNITUDE``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ...bilabial_lead import MAX_LEAD_S
from ...errors import InvalidRequestError
from ...features import DEFAULT_MFCC, MfccConfig, SpeakerPrior, StreamingNormalizer
from ...model_checks import ArrayReader, FieldReader
from ...numerics.basis import MotionBasis, read_components
from ...numerics.direct_call import DirectCall
from ...numerics.trellis import predecessors
from ...phonemes import PHONEMES
from ...store import ARRAYS_NAME, MANIFEST_NAME, ModelManifest
from ...timeline import EMOTION_INDEX, EMOTIONS
from ..base import (
    AUDIO_ONLY_UNSUPPORTED,
    Lookahead,
    Model,
    Rung,
    SynthesisRequest,
    Synthesizer,
    resolved_rung,
)
from . import kernels, trajectory
from .gaussian import Gaussians
from .synthesizer import AUDIO, AUTO, BOTH, DRIVES, HmmSynthesizer, Plan

MAX_OPTION_MS = 5000.0
RUNGS: tuple[tuple[str, float, float], ...] = (  # name, lag_ms, window_ms
    ("full", 500.0, 250.0),
    ("short", 200.0, 100.0),
    ("causal_lead", 100.0, 0.0),
    ("causal", 0.0, 0.0),
)
NO_WAIT_BELOW_MS = 100.0
"""Rungs with a lag up to this hear audio late instead of waiting for a feature window."""
CACHED_RATES = 8
"""Trajectory terms kept for this many (rate, coupled) pairs; a request fps is any number."""
INSTANT_SAMPLING = 0.0
"""The default ``sample_offset``, and that of a model whose manifest has none (saved before
the hyperparameter existed): trained on the face at the instants j / R."""
MFCC_FIELDS = ("window_s", "n_mels", "n_coefficients", "f_min", "f_max", "pre_emphasis")


class HmmModel(Model):
    """See the module docstring."""

    engine = "hmm"
    option_names = ("lag_ms", "window_ms", "drive")

    def __init__(self, manifest: ModelManifest, arrays: Mapping[str, np.ndarray]) -> None:
        super().__init__(manifest)
        self.stored = {name: np.asarray(value) for name, value in arrays.items()}
        extra = manifest.extra
        self.hmm_fps = float(extra["hmm_fps"])
        self.synthesis_fps = float(manifest.fps)
        self.mfcc = MfccConfig(rate=self.hmm_fps, **dict(extra["mfcc"]))
        self.basis = MotionBasis(self.stored["basis_mean"], self.stored["basis_components"])
        start = self.stored["start"]
        transition = self.stored["transition"]
        with np.errstate(divide="ignore"):
            self.log_start = np.log(start)
            self.log_transition = np.log(transition)
        self.predecessors = predecessors(self.log_transition)
        self.facial = Gaussians(self.stored["means"], self.stored["covariances"])
        self.phoneme_log_probs = np.ascontiguousarray(self.stored["phoneme_log_probs"])
        self.emotion_log_probs = np.ascontiguousarray(self.stored["emotion_log_probs"])
        self.categories = np.ascontiguousarray(  # (phonemes + emotions, N)
            np.concatenate([self.phoneme_log_probs, self.emotion_log_probs], axis=1).T
        )
        self.vocal: Gaussians | None = None
        if bool(extra["has_audio"]):
            self.vocal = Gaussians(self.stored["vocal_means"], self.stored["vocal_covariances"])
        self.uses_audio = self.vocal is not None
        self.speaker_prior = _speaker_prior(extra.get("normalization"), self.stored)
        self._dynamics: dict[tuple[float, bool], trajectory.Dynamics] = {}
        self.dynamics = self.dynamics_at(self.synthesis_fps)
        # Every request's streamed calls share one DirectCall per kernel: the argument types
        # are the model's and the synthesizer's buffers', the same for every request.
        self.decode_step = DirectCall(kernels.decode)
        self.solve_step = DirectCall(kernels.solve_block)
        self.stepwise_dynamics = self.dynamics_at(self.synthesis_fps, coupled=False)
        self.audio_weight = float(manifest.hyperparameters["audio_weight"])
        self.default_lag_ms = float(manifest.hyperparameters["lag_ms"])
        self.default_window_ms = float(manifest.hyperparameters["window_ms"])
        self.sample_offset = float(manifest.hyperparameters.get("sample_offset", INSTANT_SAMPLING))
        self.bilabial_lead_s = float(manifest.hyperparameters.get("bilabial_lead_s", 0.0))
        """How far (s) /p b m/ start before their acoustic spans on the rungs that lead them
        (``leads``); 0 in a model saved before the lead existed."""

    def emotion_row(self, emotion: str) -> int:
        """The row of ``emotion``'s log-probabilities in ``categories``."""
        return int(self.phoneme_log_probs.shape[1]) + EMOTION_INDEX[emotion]

    def solve_fps(self, fps: float) -> float:
        """The rate the trajectory of a request at ``fps`` is solved at (``synthesizer``):
        the smallest whole multiple of ``fps`` that is at least ``hmm_fps`` (every HMM frame
        keeps a trajectory frame, so no state is skipped), at most the synthesis rate."""
        multiple = fps * max(1, math.ceil(self.hmm_fps / fps - 1e-9))
        return min(float(multiple), self.synthesis_fps)

    def dynamics_at(self, rate: float, coupled: bool = True) -> trajectory.Dynamics:
        """Eq. 5's terms for a trajectory solved at ``rate`` (kept for ``CACHED_RATES``
        rates)."""
        key = (float(rate), coupled)
        found = self._dynamics.get(key)
        if found is None:
            means, covariances = self.stored["means"], self.stored["covariances"]
            found = trajectory.dynamics(means, covariances, self.hmm_fps / rate, coupled)
            if len(self._dynamics) >= CACHED_RATES:
                self._dynamics.clear()
            self._dynamics[key] = found
        return found

    def normalizer(self) -> StreamingNormalizer | None:
        """A new stream's speaker normalization (None: the model hears raw features)."""
        prior = self.speaker_prior
        return None if prior is None else StreamingNormalizer(prior)

    @property
    def accepts_audio_only(self) -> bool:
        return self.vocal is not None

    @staticmethod
    def feature_config(hmm_fps: float) -> MfccConfig:
        """The speech-feature analysis at one feature frame per HMM frame."""
        return MfccConfig(rate=hmm_fps, **mfcc_fields())

    # -- options, ladder --------------------------------------------------------------------

    def resolve(self, options: Mapping[str, Any]) -> tuple[float | None, float | None]:
        """(lag_ms, window_ms) of ``options`` with the defaults filled in."""
        values: list[float | None] = []
        for name, default in (
            ("lag_ms", self.default_lag_ms),
            ("window_ms", self.default_window_ms),
        ):
            value = options.get(name, default)
            if value is None:
                values.append(None)
                continue
            if (
                isinstance(value, bool)
                or not isinstance(value, (int, float))
                or not 0.0 <= value <= MAX_OPTION_MS
            ):
                raise InvalidRequestError(
                    f"{name} must be null or a number of milliseconds in [0, {MAX_OPTION_MS:g}], "
                    f"got {value!r}",
                    where=f"options.{name}",
                )
            values.append(float(value))
        return values[0], values[1]

    def leads(self, lag_ms: float | None, drive: object) -> float:
        """The bilabial lead (s) of a request with Viterbi lag ``lag_ms`` and ``drive``: the
        model's on the rungs that wait for a feature window anyway (lag above
        ``NO_WAIT_BELOW_MS`` or unlimited) when it may read phonemes, else 0."""
        waits = lag_ms is None or lag_ms > NO_WAIT_BELOW_MS
        return self.bilabial_lead_s if waits and drive != AUDIO else 0.0

    def plan(self, options: Mapping[str, Any], fps: float | None = None) -> Plan:
        """The schedule of a request at ``fps`` (None: at the synthesis rate, the one the
        lookahead is stated for). Blocks are solved at ``solve_fps(fps)``, ``window_ms`` long
        with half a block of future context, trimmed so that the frame's wait is never longer
        than at the synthesis rate: the rung's lookahead holds at every fps. A frame at a time
        (``window_ms`` 0) stays at the synthesis rate: each step of that recursion pulls
        towards the state's pose by a gain set by the velocity precision, so its pull per
        second, unlike Eq. 5's whole-window optimum, changes with the rate."""
        lag_ms, window_ms = self.resolve(options)
        lag = None if lag_ms is None else round(lag_ms / 1000.0 * self.hmm_fps)
        frame_at_a_time = window_ms == 0.0  # its recursion's pull per second depends on the rate
        rate = self.synthesis_fps if fps is None or frame_at_a_time else self.solve_fps(fps)
        if window_ms is None:
            block, future = None, 0
        elif window_ms == 0.0:
            block, future = 1, 0
        else:
            block, future = _blocks(window_ms / 1000.0, rate, self.synthesis_fps)
        drive = options.get("drive", AUTO)
        if drive not in DRIVES:
            raise InvalidRequestError(
                f"drive must be one of {', '.join(DRIVES)}, got {drive!r}", where="options.drive"
            )
        if drive in (AUDIO, BOTH) and self.vocal is None:
            raise InvalidRequestError(
                f"model {self.name!r} was trained without audio: it takes drive = phonemes only",
                where="options.drive",
                code=AUDIO_ONLY_UNSUPPORTED if drive == AUDIO else "invalid_request",
            )
        delay = 0
        if lag_ms is not None and lag_ms <= NO_WAIT_BELOW_MS and window_ms == 0.0:
            delay = math.ceil((self.mfcc.window_s / 2.0 + 1e-3) * self.hmm_fps)
        return Plan(lag, block, future, delay, rate, str(drive), self.leads(lag_ms, drive))

    def lookahead_for(self, options: Mapping[str, Any]) -> Lookahead | None:
        """The lookahead at the synthesis rate, which bounds the wait at every fps
        (``plan``): the spans past t the frame at t waits for, with the bilabial lead."""
        plan = self.plan(options)
        wait = plan.wait_s(self.hmm_fps)
        if wait is None:
            return None
        audio = 0.0 if plan.delay or self.vocal is None else self.mfcc.window_s / 2.0
        return Lookahead(seconds=wait + plan.lead_s, audio_seconds=audio)

    @property
    def lookahead(self) -> Lookahead:
        lookahead = self.lookahead_for({})
        return lookahead if lookahead is not None else Lookahead(seconds=math.inf)

    def fidelity_ladder(self) -> tuple[Rung, ...]:
        rungs = []
        for name, lag_ms, window_ms in RUNGS:
            options = {"lag_ms": lag_ms, "window_ms": window_ms}
            lookahead = self.lookahead_for(options)
            assert lookahead is not None
            rungs.append(Rung(name, lookahead, options))
        return tuple(rungs)

    def rung_for(self, options: Mapping[str, Any]) -> Rung | None:
        return resolved_rung(self.fidelity_ladder(), options, self.resolve)

    def synthesizer(self, request: SynthesisRequest) -> Synthesizer:
        return HmmSynthesizer(self, request, self.plan(request.options, request.fps))

    # -- store ------------------------------------------------------------------------------

    def arrays(self) -> dict[str, np.ndarray]:
        return dict(self.stored)

    @classmethod
    def from_arrays(
        cls, manifest: ModelManifest, arrays: Mapping[str, np.ndarray], path: Path
    ) -> HmmModel:
        fields = FieldReader(str(path / MANIFEST_NAME))
        hyper = fields.mapping(manifest.hyperparameters, "hyperparameters")
        extra = fields.mapping(manifest.extra, "extra")
        fields.number(
            fields.member(hyper, "audio_weight", "hyperparameters.audio_weight"),
            "hyperparameters.audio_weight",
            0.0,
            100.0,
        )
        for name in ("lag_ms", "window_ms"):
            fields.number(
                fields.member(hyper, name, f"hyperparameters.{name}"),
                f"hyperparameters.{name}",
                0.0,
                MAX_OPTION_MS,
            )
        if "sample_offset" in hyper:
            fields.number(hyper["sample_offset"], "hyperparameters.sample_offset", 0.0, 1.0)
        if "bilabial_lead_s" in hyper:  # absent from models saved before it: no lead
            fields.number(
                hyper["bilabial_lead_s"], "hyperparameters.bilabial_lead_s", 0.0, MAX_LEAD_S
            )
        fields.number(
            fields.member(extra, "hmm_fps", "extra.hmm_fps"), "extra.hmm_fps", 1.0, 1000.0
        )
        has_audio = fields.flag(
            fields.member(extra, "has_audio", "extra.has_audio"), "extra.has_audio"
        )
        mfcc = fields.mapping(fields.member(extra, "mfcc", "extra.mfcc"), "extra.mfcc")
        for name in MFCC_FIELDS:
            value = fields.member(mfcc, name, f"extra.mfcc.{name}")
            if name in ("n_mels", "n_coefficients"):
                fields.integer(value, f"extra.mfcc.{name}", 1, 128)
            else:
                fields.number(value, f"extra.mfcc.{name}", 0.0, 100000.0)
        reader = ArrayReader(arrays, str(path / ARRAYS_NAME))
        checked = check_arrays(reader, len(manifest.channels), has_audio)
        normalization = extra.get("normalization")
        if normalization is not None:
            if not has_audio:
                raise fields.error("extra.normalization", "must be null without audio")
            width = checked["vocal_means"].shape[1]
            mapping = fields.mapping(normalization, "extra.normalization")
            _check_normalization(fields, mapping, width)
            checked["vocal_prior_mean"] = reader.floats("vocal_prior_mean", (width,))
            checked["vocal_prior_variance"] = reader.floats("vocal_prior_variance", (width,), 1e-12)
        return cls(manifest, checked)


def _blocks(window_s: float, rate: float, synthesis_fps: float) -> tuple[int, int]:
    """(block, future) in frames at ``rate`` for blocks ``window_s`` long with half a block of
    future context, cut so that (block − 1 + future) / rate, the wait they add, is at most
    what it is at ``synthesis_fps``."""
    widest = max(1, round(window_s * synthesis_fps))
    budget = (widest - 1 + widest // 2) / synthesis_fps
    frames = math.floor(budget * rate + 1e-9)  # block − 1 + future may not exceed this
    block = max(1, min(round(window_s * rate), frames + 1))
    return block, max(0, min(block // 2, frames - (block - 1)))


NORMALIZATION_FIELDS = ("prior_frames", "gate_nats", "silence_energy", "energy_column")


def normalization_fields(prior: SpeakerPrior | None) -> dict[str, Any] | None:
    """The speaker normalization's scalars as stored in ``extra.normalization`` (its mean
    and variance are the arrays ``vocal_prior_mean`` and ``vocal_prior_variance``); None
    for a model that hears raw features."""
    if prior is None:
        return None
    return {name: getattr(prior, name) for name in NORMALIZATION_FIELDS}


def _speaker_prior(
    normalization: Mapping[str, Any] | None, arrays: Mapping[str, np.ndarray]
) -> SpeakerPrior | None:
    """The stored prior; a model saved before speaker normalization (no
    ``extra.normalization``) hears raw features, as it was trained to."""
    if normalization is None:
        return None
    return SpeakerPrior(
        np.asarray(arrays["vocal_prior_mean"], dtype=np.float64),
        np.asarray(arrays["vocal_prior_variance"], dtype=np.float64),
        float(normalization["prior_frames"]),
        float(normalization["gate_nats"]),
        float(normalization["silence_energy"]),
        int(normalization["energy_column"]),
    )


def _check_normalization(fields: FieldReader, normalization: Mapping[str, Any], width: int) -> None:
    for name in NORMALIZATION_FIELDS:
        where = f"extra.normalization.{name}"
        value = fields.member(normalization, name, where)
        if name == "energy_column":
            fields.integer(value, where, 0, width - 1)
        elif name == "silence_energy":
            fields.number(value, where, -1000.0, 1000.0)
        else:  # a prior of no weight would leave the first frames' mean 0 / 0
            fields.number(value, where, 0.0, 100000.0, above=name == "prior_frames")


def mfcc_fields(config: MfccConfig = DEFAULT_MFCC) -> dict[str, Any]:
    """The feature analysis as stored in ``extra.mfcc`` (the rate is ``hmm_fps``)."""
    return {name: getattr(config, name) for name in MFCC_FIELDS}


def _check_spd(reader: ArrayReader, name: str, matrices: np.ndarray) -> None:
    if not np.allclose(matrices, np.swapaxes(matrices, 1, 2), rtol=1e-6, atol=1e-9):
        raise reader.error(name, "holds a matrix that is not symmetric")
    try:
        np.linalg.cholesky(matrices)
    except np.linalg.LinAlgError:
        raise reader.error(name, "holds a matrix that is not positive definite") from None


def check_arrays(reader: ArrayReader, n_channels: int, has_audio: bool) -> dict[str, np.ndarray]:
    """Every array read with kind, shape and range checked."""
    mean = reader.floats("basis_mean", (n_channels,))
    components = read_components(reader, "basis_components", n_channels)
    dim = 2 * len(components)
    start = reader.floats("start", (None,))
    n = len(start)
    if n == 0:
        raise reader.error("start", "is empty: a model needs at least one state")
    transition = reader.floats("transition", (n, n))
    for name, values in (("start", start), ("transition", transition)):
        if (values < 0.0).any() or np.abs(values.sum(axis=-1) - 1.0).max() > 1e-6:
            raise reader.error(name, "must hold probabilities summing to 1")
    means = reader.floats("means", (n, dim))
    covariances = reader.floats("covariances", (n, dim, dim))
    _check_spd(reader, "covariances", covariances)
    categoricals = {}
    for name, width in (("phoneme_log_probs", len(PHONEMES)), ("emotion_log_probs", len(EMOTIONS))):
        values = reader.floats(name, (n, width))
        if (values > 1e-9).any() or np.abs(np.exp(values).sum(axis=1) - 1.0).max() > 1e-6:
            raise reader.error(name, "must hold log-probabilities summing to 1")
        categoricals[name] = values
    vocal_means = reader.floats("vocal_means", (n, None))
    width = vocal_means.shape[1]
    if has_audio != (width > 0):
        raise reader.error("vocal_means", "must have columns exactly when extra.has_audio")
    vocal_covariances = reader.floats("vocal_covariances", (n, width, width))
    if has_audio:
        _check_spd(reader, "vocal_covariances", vocal_covariances)
    return {
        "basis_mean": mean,
        "basis_components": components,
        "start": start,
        "transition": transition,
        "means": means,
        "covariances": covariances,
        **categoricals,
        "vocal_means": vocal_means,
        "vocal_covariances": vocal_covariances,
    }
