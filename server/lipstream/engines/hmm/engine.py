"""The ``hmm`` engine: voice puppetry (Brand 1999), trained by ``fit``.

the motion basis (PCA keeping ``variance`` of every channel's variance) ->
observations [pose, velocity] at ``hmm_fps`` (HMM frame j the curves at
(j + ``sample_offset``) / ``hmm_fps``, by default its instant j / ``hmm_fps``;
velocity the backward difference per HMM frame) -> the facial HMM trained from a large
fully connected model (``em``: entropic with extinction, or Baum-Welch as the
comparison) on the inner training split -> γ on every training line ->
remapping (``remap``): phoneme and emotion categoricals (each HMM frame's phoneme read from
the spans with every /p b m/ started ``bilabial_lead_s`` earlier, ``bilabial_lead``, as the
rungs that lead read them), and speech-feature
Gaussians when every line has audio (each line's features normalized as a served stream
normalizes them, ``features.StreamingNormalizer``, from a prior pooled over the training
lines' speech frames, when ``speaker_normalization``) -> metrics: perplexity,
held-out entropy rate (bits per frame of the facial state posterior on the inner
held-out lines), states surviving.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from ...bilabial_lead import MAX_LEAD_S, lead_bilabials
from ...corpus import Corpus, Utterance
from ...features import (
    SpeakerPrior,
    StreamingNormalizer,
    speaker_prior,
    speech_features,
)
from ...numerics.basis import MotionBasis, fit_basis
from ...numerics.resample import interp_columns
from ...numerics.trellis import forward_backward
from ...phonemes import PHONEME_INDEX, PHONEMES
from ...timeline import EMOTIONS
from ..base import Engine, frame_count
from . import em, remap
from .model import HmmModel, mfcc_fields, normalization_fields

VOCAL_FLOOR = 1e-3
HMM_FPS = 60.0
"""The default ``hmm_fps``. At 40 Hz the closures on the real-face set's phones came 2 to 23 ms
behind the real lips over four EM seeds, at 60 Hz -1 to +6 ms, with the demo's held-out RMS
about as it was (``bench.hmm_rate``; docs/explanation/engines/hmm.md, "The HMM frame rate")."""
HMM_PRIOR_FRAMES = HMM_FPS
"""The default ``prior_frames``: the speaker prior is worth one second of speech frames."""
HOLD_CENTRE = 0.5
"""``sample_offset`` for a pose trained on the face at the centre of the interval the
synthesizer holds state j over, [j / R, (j + 1) / R) (``synthesizer.hmm_frame``); its phoneme
label and speech features stay at j / R, where the synthesizer reads them. Not the default:
over four EM seeds it did not move the demo's closures beyond the seeds' spread and made the
voice-driven ``causal`` rung worse (docs/explanation/engines/hmm.md)."""
HMM_BILABIAL_LEAD_S = 0.08
"""The default ``bilabial_lead_s``: the pick of ``bench.bilabial_lead_sweep``
(``closure_timing.best_lead_ms``, four EM seeds, ``full`` rung): the lead whose closures sit
nearest the character's both on the demo's held-out lines and on the real-face set's phones,
without the held-out RMS rising above the unled model's."""


def hmm_times(utterance: Utterance, hmm_fps: float) -> np.ndarray:
    """Times (s) of the HMM frames of an utterance: j / hmm_fps up to its last frame."""
    return np.arange(frame_count(utterance.duration, hmm_fps)) / hmm_fps


def observations(
    utterance: Utterance, basis: MotionBasis, hmm_fps: float, sample_offset: float = HOLD_CENTRE
) -> np.ndarray:
    """[pose, velocity] (T, 2D) at the HMM rate, frame j the curves at (j + ``sample_offset``)
    / ``hmm_fps`` (linear interpolation; past the last frame, the last frame); frame 0's
    velocity is frame 1's."""
    times = hmm_times(utterance, hmm_fps) + sample_offset / hmm_fps
    pose = basis.project(utterance.frames)
    sampled = interp_columns(times, utterance.times(), pose)
    velocity = np.diff(sampled, axis=0, prepend=sampled[:1])
    if len(sampled) > 1:
        velocity[0] = velocity[1]
    return np.concatenate([sampled, velocity], axis=1)


def phoneme_labels(utterance: Utterance, hmm_fps: float, lead_s: float = 0.0) -> np.ndarray:
    """Phoneme index of each HMM frame: the span with start < t ≤ end (frame 0: the first),
    the spans' bilabials led by ``lead_s`` (``bilabial_lead.lead_bilabials``)."""
    times = hmm_times(utterance, hmm_fps)
    phones = lead_bilabials(utterance.phones, lead_s) if lead_s > 0.0 else utterance.phones
    starts = np.array([span.start for span in phones])
    index = np.clip(np.searchsorted(starts, times - 1e-9, side="left") - 1, 0, None)
    return np.array([PHONEME_INDEX[phones[k].phoneme] for k in index], dtype=np.int64)


class HmmEngine(Engine):
    """Voice puppetry; hyperparameters as in docs/explanation/engines/hmm.md."""

    name = "hmm"
    model_class = HmmModel

    def __init__(
        self,
        *,
        n_states: int = 40,
        hmm_fps: float = HMM_FPS,
        variance: float = 0.95,
        estimator: str = em.ENTROPIC,
        prior_scale: float = 1.0,
        covariance_floor: float = 0.05,
        n_iter: int = 15,
        max_training_frames: int = 12000,
        tol: float = 1e-4,
        phoneme_smoothing: float = 0.5,
        audio_weight: float = 0.1,
        seed: int = 0,
        lag_ms: float = 500.0,
        window_ms: float = 250.0,
        speaker_normalization: bool = True,
        prior_frames: float = HMM_PRIOR_FRAMES,
        sample_offset: float = 0.0,
        bilabial_lead_s: float = HMM_BILABIAL_LEAD_S,
    ) -> None:
        self.n_states = n_states
        self.hmm_fps = hmm_fps
        self.variance = variance
        self.estimator = estimator
        self.prior_scale = prior_scale
        self.covariance_floor = covariance_floor
        self.n_iter = n_iter
        self.max_training_frames = max_training_frames
        self.tol = tol
        self.phoneme_smoothing = phoneme_smoothing
        self.audio_weight = audio_weight
        self.seed = seed
        self.lag_ms = lag_ms
        self.window_ms = window_ms
        self.speaker_normalization = speaker_normalization
        self.prior_frames = prior_frames
        self.sample_offset = sample_offset
        self.bilabial_lead_s = bilabial_lead_s

    def settings(self) -> em.Settings:
        if self.estimator not in em.ESTIMATORS:
            raise ValueError(f"estimator must be one of {em.ESTIMATORS}, got {self.estimator!r}")
        if not 0.0 <= self.sample_offset < 1.0:
            raise ValueError(f"sample_offset must be in [0, 1), got {self.sample_offset!r}")
        if not 0.0 <= self.bilabial_lead_s <= MAX_LEAD_S:
            raise ValueError(
                f"bilabial_lead_s must be in [0, {MAX_LEAD_S:g}], got {self.bilabial_lead_s!r}"
            )
        return em.Settings(
            n_states=self.n_states,
            estimator=self.estimator,
            z=self.prior_scale,
            covariance_floor=self.covariance_floor,
            n_iter=self.n_iter,
            tol=self.tol,
            seed=self.seed,
        )

    def fit(self, corpus: Any, *, progress: bool = False) -> HmmModel:
        began = time.perf_counter()
        settings = self.settings()
        recorded = np.concatenate([utterance.frames for utterance in corpus.utterances])
        basis, _ = fit_basis(recorded, self.variance)
        inner, heldout = corpus.split() if len(corpus.utterances) >= 10 else (corpus, None)
        with threadpool_limits(limits=1):
            sequences = _evenly(
                [
                    observations(u, basis, self.hmm_fps, self.sample_offset)
                    for u in inner.utterances
                ],
                self.max_training_frames,
            )
            fitted = em.fit(sequences, settings)
            parameters = fitted.parameters
            everything = [
                observations(u, basis, self.hmm_fps, self.sample_offset) for u in corpus.utterances
            ]
            gammas = _gammas(parameters, everything)
            metrics = self._metrics(fitted, heldout, basis)
            arrays, prior = self._remap(corpus, gammas)
        metrics["training_s"] = round(time.perf_counter() - began, 3)
        manifest = self.new_manifest(
            corpus,
            metrics=metrics,
            extra={
                "hmm_fps": float(self.hmm_fps),
                "has_audio": arrays["vocal_means"].shape[1] > 0,
                "mfcc": mfcc_fields(),
                "normalization": normalization_fields(prior),
            },
        )
        arrays.update(
            basis_mean=basis.mean,
            basis_components=basis.components,
            start=parameters.start,
            transition=parameters.transition,
            means=parameters.means,
            covariances=parameters.covariances,
        )
        return HmmModel(manifest, arrays)

    def _metrics(
        self, fitted: em.FitResult, heldout: Corpus | None, basis: MotionBasis
    ) -> dict[str, Any]:
        parameters = fitted.parameters
        metrics: dict[str, Any] = {
            "estimator": self.estimator,
            "states_initial": self.n_states,
            "states": parameters.n_states,
            "transitions": int((parameters.transition > 0.0).sum()),
            "perplexity": round(em.perplexity(parameters, fitted.statistics.occupancy), 6),
            "log_posterior": [round(value, 3) for value in fitted.history],
            "train_entropy_rate_bits": round(
                fitted.statistics.entropy / fitted.statistics.frames / math.log(2.0), 6
            ),
            "heldout_entropy_rate_bits": None,
        }
        if heldout is not None and heldout.utterances:
            held = [
                observations(u, basis, self.hmm_fps, self.sample_offset) for u in heldout.utterances
            ]
            stats = em.e_step(parameters, held)
            metrics["heldout_entropy_rate_bits"] = round(
                stats.entropy / stats.frames / math.log(2.0), 6
            )
            metrics["heldout_log_likelihood_per_frame"] = round(
                stats.log_likelihood / stats.frames, 6
            )
        return metrics

    def _remap(
        self, corpus: Corpus, gammas: list[np.ndarray]
    ) -> tuple[dict[str, np.ndarray], SpeakerPrior | None]:
        utterances = corpus.utterances
        labels = [phoneme_labels(u, self.hmm_fps, self.bilabial_lead_s) for u in utterances]
        emotions = [
            np.full(len(gamma), EMOTIONS.index(u.emotion), dtype=np.int64)
            for u, gamma in zip(utterances, gammas, strict=True)
        ]
        arrays = {
            "phoneme_log_probs": remap.phoneme_log_probabilities(
                gammas, labels, len(PHONEMES), self.phoneme_smoothing
            ),
            "emotion_log_probs": remap.phoneme_log_probabilities(
                gammas, emotions, len(EMOTIONS), self.phoneme_smoothing
            ),
        }
        n = gammas[0].shape[1]
        prior = None
        if all(u.audio is not None for u in utterances):
            config = HmmModel.feature_config(self.hmm_fps)
            features = []
            for utterance, gamma in zip(utterances, gammas, strict=True):
                audio = utterance.audio
                assert audio is not None
                rows = speech_features(audio.samples, audio.sample_rate, 0, len(gamma), config)
                features.append(rows)
            if self.speaker_normalization:
                prior = speaker_prior(features, config.n_coefficients, self.prior_frames)
                features = [StreamingNormalizer(prior).apply(rows) for rows in features]
                arrays["vocal_prior_mean"] = prior.mean
                arrays["vocal_prior_variance"] = prior.variance
            means, covariances = remap.vocal_gaussians(gammas, features, VOCAL_FLOOR)
        else:
            means, covariances = np.zeros((n, 0)), np.zeros((n, 0, 0))
        arrays["vocal_means"] = means
        arrays["vocal_covariances"] = covariances
        return arrays, prior


def _evenly(sequences: list[np.ndarray], max_frames: int) -> list[np.ndarray]:
    """Every k-th sequence, k the smallest step that keeps the total within ``max_frames``
    (at least one sequence)."""
    total = sum(len(sequence) for sequence in sequences)
    step = max(1, math.ceil(total / max(1, max_frames)))
    return sequences[::step]


def _gammas(parameters: em.HmmParameters, sequences: list[np.ndarray]) -> list[np.ndarray]:
    gaussians = parameters.gaussians()
    log_start = parameters.log_start()
    return [
        forward_backward(log_start, parameters.transition, gaussians.log_density(s)).gamma
        for s in sequences
    ]
