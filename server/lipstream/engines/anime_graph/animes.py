"""Animes: the corpus cut into phoneme-long motion fragments with their audio.

Sketch: every phone span of every training utterance becomes one anime
A = <P, C, M> (Cao et al. 2004, §5.1): its phoneme label P, the MFCC curve C
under the span (when the corpus has audio) and its motion M, the PCA
coefficients of the recording between the span's start and end. Fragments
are not copied: an anime is (utterance, start s, end s) into per-utterance
curves, sampled by linear interpolation, so consecutive animes of a
recording join exactly and a fragment can be read past its ends (the
recording continues, or is extrapolated by its end velocity).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from ...audio import Audio
from ...errors import CorpusError
from ...features import MfccConfig, frame_count, mfcc
from ...numerics.basis import MotionBasis
from ...numerics.resample import extend_into
from ...phonemes import PHONEME_INDEX

if TYPE_CHECKING:
    from ...corpus import Corpus

SUMMARY_POINTS = 4
"""Points per anime of the audio-feature summary used to rank candidates."""

SHAPE_POINTS = 12
"""Samples per anime of the duration-normalized motion used for clustering."""


@dataclass(frozen=True)
class Curves:
    """Per-utterance curves stacked: ``values`` (n_samples, dim) at ``rate`` Hz; utterance u
    owns rows ``offsets[u]:offsets[u + 1]``, its sample k at k / rate seconds."""

    values: np.ndarray
    offsets: np.ndarray
    rate: float

    @property
    def dim(self) -> int:
        return int(self.values.shape[1])

    def rows(self, utterance: int) -> np.ndarray:
        return self.values[int(self.offsets[utterance]) : int(self.offsets[utterance + 1])]

    def sample(self, utterance: np.ndarray, times: np.ndarray, *, extrapolate: bool) -> np.ndarray:
        """Values at ``times`` (s, shape (n,)) of ``utterance`` (n,), float64 (n, dim).

        Outside an utterance the first/last segment is continued linearly
        (``extrapolate``) or its end value is held.
        """
        return _interpolate(
            self.values,
            np.asarray(self.offsets, dtype=np.int64),
            np.asarray(utterance, dtype=np.int64),
            np.asarray(times, dtype=np.float64),
            float(self.rate),
            extrapolate,
        )


@njit(cache=True)
def _interpolate(
    values: np.ndarray,
    offsets: np.ndarray,
    utterance: np.ndarray,
    times: np.ndarray,
    rate: float,
    extrapolate: bool,
) -> np.ndarray:
    """``Curves.sample``, compiled: it runs for every fragment placed, and as numpy calls
    its fixed cost dwarfed the few rows it reads."""
    out = np.empty((len(times), values.shape[1]))
    for row in range(len(times)):
        sample_into(out[row], values, offsets, utterance[row], times[row], rate, extrapolate)
    return out


@njit(cache=True)
def sample_into(
    out: np.ndarray,
    values: np.ndarray,
    offsets: np.ndarray,
    utterance: int,
    time: float,
    rate: float,
    extrapolate: bool,
) -> None:
    """One row of ``Curves.sample``: utterance ``utterance`` at ``time`` (s) into ``out``
    (dim,)."""
    first = offsets[utterance]
    last = offsets[utterance + 1] - 1 - first
    position = time * rate
    if not extrapolate:
        position = min(max(position, 0.0), float(last))
    low = int(min(max(math.floor(position), 0.0), float(max(last - 1, 0))))
    high = min(low + 1, last)
    fraction = position - low if high > low else 0.0
    # the line form (not blend_into, which rounds differently): it continues the end segments
    extend_into(out, values, first + low, first + high, fraction)


@dataclass(frozen=True)
class AnimeTable:
    """Every anime of the corpus, in recording order; n = number of animes.

    ``labels`` (n,) phoneme indices (``lipstream.phonemes.PHONEME_INDEX``),
    ``utterance`` (n,), ``start``/``end`` (n,) seconds in their utterance,
    ``motion`` PCA curves at the corpus fps, ``features`` MFCC curves or None.
    """

    labels: np.ndarray
    utterance: np.ndarray
    start: np.ndarray
    end: np.ndarray
    motion: Curves
    features: Curves | None

    @property
    def size(self) -> int:
        return len(self.labels)

    def successors(self) -> np.ndarray:
        """(n,) the next anime of the same recording, or -1 at a recording's end."""
        following = np.arange(1, self.size + 1, dtype=np.int32)
        same = np.zeros(self.size, dtype=bool)
        same[:-1] = self.utterance[1:] == self.utterance[:-1]
        return np.where(same, following, -1).astype(np.int32)

    def poses_at(self, animes: np.ndarray, where: float) -> np.ndarray:
        """Motion at relative time ``where`` in [0, 1] of each anime: (len(animes), n_pc)."""
        times = self.start[animes] + where * (self.end[animes] - self.start[animes])
        return self.motion.sample(self.utterance[animes], times, extrapolate=True)

    def shapes(self, points: int = SHAPE_POINTS) -> np.ndarray:
        """Duration-normalized motion: ``points`` evenly spaced samples of every anime,
        flattened to (n, points * n_pc)."""
        relative = np.linspace(0.0, 1.0, points)
        times = self.start[:, None] + relative[None, :] * (self.end - self.start)[:, None]
        owners = np.repeat(self.utterance, points)
        values = self.motion.sample(owners, times.ravel(), extrapolate=True)
        return values.reshape(self.size, points * self.motion.dim)

    def summaries(self) -> np.ndarray:
        """Audio summaries (n, SUMMARY_POINTS * n_mfcc), or (n, 0) without audio."""
        if self.features is None:
            return np.zeros((self.size, 0), dtype=np.float32)
        return summarize(self.features, self.utterance, self.start, self.end)


def summarize(
    features: Curves, utterance: np.ndarray, start: np.ndarray, end: np.ndarray
) -> np.ndarray:
    """The feature curve under each span (start, end in s), sampled at the centres of
    ``SUMMARY_POINTS`` equal parts: float32 (n_spans, SUMMARY_POINTS * dim)."""
    relative = (np.arange(SUMMARY_POINTS) + 0.5) / SUMMARY_POINTS
    times = start[:, None] + relative[None, :] * (end - start)[:, None]
    owners = np.repeat(np.asarray(utterance), SUMMARY_POINTS)
    values = features.sample(owners, times.ravel(), extrapolate=False)
    return values.reshape(len(start), SUMMARY_POINTS * features.dim).astype(np.float32)


def _stack(blocks: list[np.ndarray], dim: int, rate: float, dtype: type) -> Curves:
    offsets = np.zeros(len(blocks) + 1, dtype=np.int64)
    offsets[1:] = np.cumsum([len(block) for block in blocks])
    values = np.concatenate(blocks) if blocks else np.zeros((0, dim))
    return Curves(np.ascontiguousarray(values, dtype=dtype), offsets, rate)


def utterance_features(audio: Audio, until_s: float, config: MfccConfig) -> np.ndarray:
    """MFCC frames of one recording covering at least [0, until_s]."""
    stop = frame_count(max(audio.duration, until_s), config)
    return mfcc(audio.samples, audio.sample_rate, 0, stop, config)


def segment_corpus(
    corpus: Corpus, basis: MotionBasis, config: MfccConfig, use_audio: bool
) -> AnimeTable:
    """Cut every utterance of ``corpus`` into animes."""
    utterances = list(corpus.utterances)
    labels: list[int] = []
    owners: list[int] = []
    starts: list[float] = []
    ends: list[float] = []
    motion: list[np.ndarray] = []
    features: list[np.ndarray] = []
    for index, utterance in enumerate(utterances):
        if not utterance.phones:
            raise CorpusError("utterance has no phones", where=f"utterance {utterance.stem!r}")
        for span in utterance.phones:
            labels.append(PHONEME_INDEX[span.phoneme])
            owners.append(index)
            starts.append(span.start)
            ends.append(span.end)
        motion.append(basis.project(utterance.frames).astype(np.float32))
        if use_audio:
            if utterance.audio is None:
                raise CorpusError(
                    "utterance has no audio while the others have",
                    where=f"utterance {utterance.stem!r}",
                )
            features.append(utterance_features(utterance.audio, utterance.phones[-1].end, config))
    fps = float(corpus.fps)
    return AnimeTable(
        labels=np.asarray(labels, dtype=np.int16),
        utterance=np.asarray(owners, dtype=np.int32),
        start=np.asarray(starts, dtype=np.float64),
        end=np.asarray(ends, dtype=np.float64),
        motion=_stack(motion, basis.n_components, fps, np.float32),
        features=_stack(features, config.n_coefficients, config.rate, np.float32)
        if use_audio
        else None,
    )
