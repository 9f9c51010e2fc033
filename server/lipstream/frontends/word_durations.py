"""How long each phoneme of a word lasts: a duration model trained on a corpus's phone
alignments, and the files every trained model directory carries it in.

Method: the log duration of a phoneme is modelled (least squares, ridge ``ridge``) from
the phoneme itself, the classes of its left and right neighbours (silence, vowel, stop,
fricative, nasal, approximant) and the local speaking rate, with a slope per phoneme
class (vowels stretch more than stops). The local rate of a phoneme is the mean, over
the non-silent phonemes within ``window`` of it (itself excluded), of how much longer
than its phoneme's mean each one is, in log units. ``fit`` reads as its three stages:
per-phoneme means, the regression, the residual spread per phoneme. To spread a word
(``spread_words``): a first pass gives each phoneme its mean scaled to the word, which
gives the local rates; the model predicts log durations a_i with spreads s_i, and the
word's time T is shared as exp(a_i + λ s_i²) with λ such that they sum to T (a
phoneme that varies more absorbs more of the difference, as HTS-style duration models
share a length). Stored as ``word_durations.json`` (hyperparameters, layout, metrics)
beside ``word_durations.npz`` (arrays, no pickle) in a model directory.
"""

from __future__ import annotations

import json
import math
import zipfile
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ModelStoreError
from ..model_checks import ArrayReader, FieldReader
from ..phonemes import PHONEME_INDEX, PHONEMES, SILENCE
from ..store import open_regular
from ..timeline import PhonemeSpan

MANIFEST_FILE = "word_durations.json"
ARRAYS_FILE = "word_durations.npz"
FORMAT_VERSION = 1
MAX_MANIFEST_BYTES = 1 << 16
CLASSES = ("silence", "vowel", "stop", "fricative", "nasal", "approximant")
_CLASS_OF = {SILENCE: 0} | {
    phoneme: CLASSES.index(kind)
    for kind, members in (
        ("vowel", "AA AE AH AO AW AY EH ER EY IH IY OW OY UH UW"),
        ("stop", "B D G K P T"),
        ("fricative", "CH DH F HH JH S SH TH V Z ZH"),
        ("nasal", "M N NG"),
        ("approximant", "L R W Y"),
    )
    for phoneme in members.split()
}
PHONEME_CLASS = np.array([_CLASS_OF[phoneme] for phoneme in PHONEMES], dtype=np.int64)
N_FEATURES = len(PHONEMES) + 3 * len(CLASSES)
LOG_RANGE = (math.log(1e-3), math.log(60.0))
MIN_SPREAD = 0.05
"""Floor of a phoneme's log spread, so every phoneme takes a share of a word's stretch."""
MIN_DURATION_S = 1e-3


class WordDurationModel:
    """Phoneme durations from phoneme, neighbours and local rate.

    Hyperparameters: ``window`` (phonemes each side for the local rate), ``ridge``.
    Fitted: ``log_mean_`` (n_phonemes,) mean log seconds; ``coef_`` (N_FEATURES,);
    ``spread_`` (n_phonemes,) residual standard deviation in log units.
    """

    def __init__(self, window: int = 4, ridge: float = 1.0) -> None:
        self.window = window
        self.ridge = ridge
        self.log_mean_ = np.zeros(len(PHONEMES))
        self.coef_ = np.zeros(N_FEATURES)
        self.spread_ = np.full(len(PHONEMES), MIN_SPREAD)
        self.metrics_: dict[str, float] = {}

    def fit(self, alignments: Iterable[Sequence[PhonemeSpan]]) -> WordDurationModel:
        """Learn from contiguous spans, one sequence per utterance."""
        utterances = [_indexed(spans) for spans in alignments]
        self.log_mean_ = _phoneme_means(utterances)
        features, targets, phonemes = self._design(utterances)
        self.coef_ = _ridge(features, targets, self.ridge)
        residuals = targets - features @ self.coef_
        self.spread_ = _phoneme_spreads(residuals, phonemes)
        self.metrics_ = {
            "spans": float(len(targets)),
            "rmse_log": float(np.sqrt(np.mean(residuals**2))),
        }
        return self

    def _design(self, utterances: list[tuple[np.ndarray, np.ndarray]]) -> tuple[Any, Any, Any]:
        rows, targets, phonemes = [], [], []
        for ids, log_durations in utterances:
            rates = self.local_rates(ids, log_durations)
            speech = ids != PHONEME_INDEX[SILENCE]
            rows.append(self.features(ids, rates)[speech])
            targets.append(log_durations[speech])
            phonemes.append(ids[speech])
        if not rows or sum(len(target) for target in targets) == 0:
            raise ValueError("no spoken phoneme to learn durations from")
        return np.concatenate(rows), np.concatenate(targets), np.concatenate(phonemes)

    def local_rates(self, ids: np.ndarray, log_durations: np.ndarray) -> np.ndarray:
        """Each phoneme's local rate, (n,) log units: mean excess of its non-silent
        neighbours within ``window`` over their phonemes' means (0 with none)."""
        excess = log_durations - self.log_mean_[ids]
        speech = (ids != PHONEME_INDEX[SILENCE]).astype(np.float64)
        sums = _window_sums(excess * speech, self.window) - excess * speech
        counts = _window_sums(speech, self.window) - speech
        return np.where(counts > 0.5, sums / np.maximum(counts, 1.0), 0.0)

    @staticmethod
    def features(ids: np.ndarray, rates: np.ndarray) -> np.ndarray:
        """The (n, N_FEATURES) design rows of a phoneme sequence: phoneme, left and right
        class (silence beyond the ends), rate by class."""
        n = len(ids)
        classes = PHONEME_CLASS[ids]
        left = np.concatenate([[0], classes[:-1]])
        right = np.concatenate([classes[1:], [0]])
        rows = np.zeros((n, N_FEATURES))
        k = len(PHONEMES)
        c = len(CLASSES)
        every = np.arange(n)
        rows[every, ids] = 1.0
        rows[every, k + left] = 1.0
        rows[every, k + c + right] = 1.0
        rows[every, k + 2 * c + classes] = rates
        return rows

    def predict_log(self, ids: np.ndarray, rates: np.ndarray) -> np.ndarray:
        """Predicted log seconds of each phoneme, (n,)."""
        return np.asarray(self.features(ids, rates) @ self.coef_)

    def save(self, directory: Path) -> None:
        """Write the model's two files into ``directory`` (a model directory)."""
        directory.mkdir(parents=True, exist_ok=True)
        manifest = {
            "format_version": FORMAT_VERSION,
            "hyperparameters": {"window": self.window, "ridge": self.ridge},
            "phoneme_set": list(PHONEMES),
            "classes": list(CLASSES),
            "metrics": self.metrics_,
        }
        with open(directory / ARRAYS_FILE, "wb") as handle:
            np.savez(handle, log_mean=self.log_mean_, coef=self.coef_, spread=self.spread_)
        text = json.dumps(manifest, indent=2, sort_keys=True, allow_nan=False) + "\n"
        (directory / MANIFEST_FILE).write_text(text, encoding="utf-8")

    @classmethod
    def load(cls, directory: Path) -> WordDurationModel:
        """The model stored in ``directory``; ``model_invalid`` naming the file and field."""
        manifest = _read_manifest(directory / MANIFEST_FILE)
        fields = FieldReader(str(directory / MANIFEST_FILE))
        if manifest.get("format_version") != FORMAT_VERSION:
            raise fields.error("format_version", f"must be {FORMAT_VERSION}")
        if manifest.get("phoneme_set") != list(PHONEMES):
            raise fields.error("phoneme_set", "is not this lipstream's phoneme set")
        if manifest.get("classes") != list(CLASSES):
            raise fields.error("classes", "are not this lipstream's phoneme classes")
        hyper = fields.mapping(manifest.get("hyperparameters"), "hyperparameters")
        window = fields.integer(hyper.get("window"), "hyperparameters.window", 1, 100)
        ridge = fields.number(hyper.get("ridge"), "hyperparameters.ridge", 0.0, 1e6)
        model = cls(window, ridge)
        reader = ArrayReader(_read_arrays(directory / ARRAYS_FILE), str(directory / ARRAYS_FILE))
        model.log_mean_ = reader.floats("log_mean", (len(PHONEMES),), *LOG_RANGE).copy()
        model.coef_ = reader.floats("coef", (N_FEATURES,), -20.0, 20.0).copy()
        model.spread_ = reader.floats("spread", (len(PHONEMES),), MIN_SPREAD, 5.0).copy()
        metrics = fields.mapping(manifest.get("metrics", {}), "metrics")
        model.metrics_ = {str(key): float(value) for key, value in metrics.items()}
        return model


def _window_sums(values: np.ndarray, half_width: int) -> np.ndarray:
    """Sum of ``values[i - half_width : i + half_width + 1]`` for every i, (n,)."""
    cumulative = np.concatenate([[0.0], np.cumsum(values)])
    every = np.arange(len(values))
    high = np.minimum(every + half_width + 1, len(values))
    low = np.maximum(every - half_width, 0)
    return np.asarray(cumulative[high] - cumulative[low])


def has_word_durations(directory: Path) -> bool:
    return (directory / MANIFEST_FILE).is_file()


def _indexed(spans: Sequence[PhonemeSpan]) -> tuple[np.ndarray, np.ndarray]:
    kept = [span for span in spans if span.end > span.start]
    ids = np.array([PHONEME_INDEX[span.phoneme] for span in kept], dtype=np.int64)
    durations = np.array([span.end - span.start for span in kept], dtype=np.float64)
    return ids, np.log(np.maximum(durations, MIN_DURATION_S))


def _phoneme_means(utterances: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    ids = np.concatenate([ids for ids, _ in utterances] or [np.zeros(0, np.int64)])
    logs = np.concatenate([logs for _, logs in utterances] or [np.zeros(0)])
    if len(ids) == 0:
        raise ValueError("no span to learn durations from")
    counts = np.bincount(ids, minlength=len(PHONEMES))
    sums = np.bincount(ids, weights=logs, minlength=len(PHONEMES))
    pooled = float(np.mean(logs))
    means = np.where(counts > 0, sums / np.maximum(counts, 1), pooled)
    return np.asarray(np.clip(means, *LOG_RANGE))


def _ridge(features: np.ndarray, targets: np.ndarray, ridge: float) -> np.ndarray:
    gram = features.T @ features + ridge * np.eye(features.shape[1])
    return np.asarray(np.linalg.solve(gram, features.T @ targets))


def _phoneme_spreads(residuals: np.ndarray, phonemes: np.ndarray) -> np.ndarray:
    counts = np.bincount(phonemes, minlength=len(PHONEMES))
    squares = np.bincount(phonemes, weights=residuals**2, minlength=len(PHONEMES))
    pooled = float(np.sqrt(np.mean(residuals**2)))
    spreads = np.where(counts >= 3, np.sqrt(squares / np.maximum(counts, 1)), pooled)
    return np.asarray(np.clip(spreads, MIN_SPREAD, 5.0))


def _read_manifest(path: Path) -> dict[str, Any]:
    if not path.is_file():
        raise ModelStoreError(
            "the model has no duration model for word timings; retrain it with "
            "`lipstream train` (or rebuild the demo with `lipstream build-demo`)",
            where=str(path),
        )
    try:
        with open_regular(path) as handle:
            raw = handle.read(MAX_MANIFEST_BYTES + 1)
        if len(raw) > MAX_MANIFEST_BYTES:
            raise ValueError(f"larger than {MAX_MANIFEST_BYTES} bytes")
        data = json.loads(raw.decode("utf-8"), parse_constant=_refuse_constant)
    except (OSError, ValueError, UnicodeDecodeError, RecursionError) as exc:
        raise ModelStoreError(f"cannot read the duration model: {exc}", where=str(path)) from None
    if not isinstance(data, dict):
        raise ModelStoreError("must hold an object", where=str(path))
    return data


def _refuse_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a JSON number")


def _read_arrays(path: Path) -> dict[str, np.ndarray]:
    try:
        with open_regular(path) as handle, np.load(handle, allow_pickle=False) as archive:
            return {name: np.asarray(archive[name]) for name in archive.files}
    except ModelStoreError:
        raise
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise ModelStoreError(f"cannot read the duration arrays: {exc}", where=str(path)) from None
