"""Per-phoneme duration statistics from the corpus alignments, shared by every engine.

Method: phoneme durations are close to log-normal, so each phoneme of the
canonical set keeps the count, mean and standard deviation of the log of its
spans' durations in the training alignments. A phoneme seen fewer than
``MIN_SPANS`` times borrows the statistics of every span pooled. The model
answers the expected (median, e^mean) duration of a phoneme; the causal rungs
scale each phoneme's filter speed by it, so a short closure is reached within
its span. The statistics are three arrays of the model file (``arrays``,
``from_arrays``); a stored median must lie between 1 ms and 60 s and a spread
between 0 and 5 log units.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..model_checks import ArrayReader
from ..phonemes import PHONEME_INDEX, PHONEMES
from ..timeline import PhonemeSpan

MIN_SPANS = 3
ARRAY_NAMES = ("duration_count", "duration_log_mean", "duration_log_std")
LOG_MEAN_RANGE = (float(np.log(1e-3)), float(np.log(60.0)))
"""Stored medians lie between 1 ms and 60 s (log seconds)."""
LOG_STD_RANGE = (0.0, 5.0)
"""Stored spreads of log seconds: 5 is a factor of e^5 (about 150) per standard deviation."""


@dataclass(frozen=True)
class DurationModel:
    """Per phoneme (``PHONEMES`` order): spans seen, mean and std of log seconds."""

    count: np.ndarray
    log_mean: np.ndarray
    log_std: np.ndarray

    @classmethod
    def fit(cls, alignments: Iterable[Iterable[PhonemeSpan]]) -> DurationModel:
        """Statistics of every span of positive length in ``alignments`` (one per utterance)."""
        logs: list[list[float]] = [[] for _ in PHONEMES]
        for spans in alignments:
            for span in spans:
                if span.end > span.start:
                    logs[PHONEME_INDEX[span.phoneme]].append(float(np.log(span.end - span.start)))
        pooled = np.array([value for values in logs for value in values])
        if len(pooled) == 0:
            raise ValueError("no span of positive length to learn durations from")
        count = np.array([len(values) for values in logs], dtype=np.int64)
        log_mean = np.full(len(PHONEMES), pooled.mean())
        log_std = np.full(len(PHONEMES), pooled.std())
        for index, values in enumerate(logs):
            if len(values) >= MIN_SPANS:
                log_mean[index] = np.mean(values)
                log_std[index] = np.std(values)
        return cls(count, log_mean, log_std)

    def expected_s(self, phoneme: str) -> float:
        """The median duration (s) of ``phoneme``."""
        return float(np.exp(self.log_mean[PHONEME_INDEX[phoneme]]))

    def expected_all_s(self) -> np.ndarray:
        """The median duration (s) of every phoneme, ``PHONEMES`` order, (n_phonemes,)."""
        return np.asarray(np.exp(self.log_mean))

    def pooled_median_s(self) -> float:
        """The median duration (s) of every span seen, pooled over the phonemes."""
        return self._pooled_median_s

    @cached_property
    def _pooled_median_s(self) -> float:
        """Once per model: a request's start reads it for every rung of its ladder."""
        weights = self.count.astype(np.float64)
        if weights.sum() == 0:
            return float(np.exp(self.log_mean.mean()))
        return float(np.exp(np.sum(weights * self.log_mean) / weights.sum()))

    def arrays(self) -> dict[str, np.ndarray]:
        return dict(zip(ARRAY_NAMES, (self.count, self.log_mean, self.log_std)))

    @classmethod
    def from_arrays(cls, reader: ArrayReader) -> DurationModel:
        """The statistics stored in a model's arrays, each checked by ``reader``."""
        shape = (len(PHONEMES),)
        count = reader.integers("duration_count", shape)
        log_mean = reader.floats("duration_log_mean", shape, *LOG_MEAN_RANGE)
        log_std = reader.floats("duration_log_std", shape, *LOG_STD_RANGE)
        if np.any(count < 0):
            raise reader.error("duration_count", "counts must not be negative")
        return cls(count.astype(np.int64), log_mean.astype(np.float64), log_std.astype(np.float64))
