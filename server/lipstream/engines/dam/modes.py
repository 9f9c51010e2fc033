"""Phoneme modes (Lin et al., Sec. 4): every occurrence of a phoneme resampled to
local time [0, 1] and clustered by affinity propagation.

Each training occurrence's curve is the cubic spline through its utterance's
frames, sampled at ``points`` evenly spaced local times from the phoneme's start
to its end (so a phoneme shorter than a frame still gets a curve). Occurrences
of one phoneme are clustered with scikit-learn's ``AffinityPropagation``
(negative squared Euclidean similarity, preference = the median similarity), so
the number of modes comes from the data. A phoneme with fewer than
``min_occurrences`` occurrences, or whose clustering does not converge, keeps
one mode (the documented fallback: too few examples to split).

Per mode we count the contexts its occurrences were seen in: the previous and
next phoneme (silence at an utterance's ends) and the utterance's emotion. A
phoneme never seen in training stands in for a seen phoneme of the same viseme
class (oculus15), else silence, else the phoneme with the most modes.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.interpolate import CubicSpline
from sklearn.cluster import AffinityPropagation
from sklearn.exceptions import ConvergenceWarning

from ...errors import CorpusError
from ...phonemes import PHONEMES, SILENCE
from ...timeline import EMOTION_INDEX, EMOTIONS, PhonemeSpan
from ...visemes import get_scheme
from ..base import SynthesisRequest

PHONEME_INDEX = {phoneme: index for index, phoneme in enumerate(PHONEMES)}
SILENCE_INDEX = PHONEME_INDEX[SILENCE]
NEUTRAL = EMOTION_INDEX["neutral"]


def emotion_index(request: SynthesisRequest, span: PhonemeSpan) -> int:
    """The index of the emotion ``span`` is spoken with (neutral when none is named)."""
    emotion = request.emotion_of(span)
    return NEUTRAL if emotion is None else EMOTION_INDEX[emotion]


@dataclass(frozen=True)
class Occurrences:
    """Every training phoneme occurrence, over the corpus's frames stacked into one array.

    ``first_row``/``rows``: the utterance's first row in the stacked frames and its frame
    count; ``start``/``duration`` in seconds from the utterance's start; ``phoneme``,
    ``previous``, ``following`` (phoneme indices), ``emotion`` (index into EMOTIONS);
    ``mode`` is filled by ``assign_modes``."""

    first_row: np.ndarray
    rows: np.ndarray
    start: np.ndarray
    duration: np.ndarray
    phoneme: np.ndarray
    previous: np.ndarray
    following: np.ndarray
    emotion: np.ndarray
    fps: float


@dataclass(frozen=True)
class Modes:
    """The modes: ``phoneme`` of each mode, grouped by phoneme with ``offsets`` (len(PHONEMES)
    + 1); context counts ``previous``/``following`` (modes x phonemes), ``emotion`` (modes x
    emotions); ``stand_in`` maps every phoneme to one that has modes."""

    phoneme: np.ndarray
    offsets: np.ndarray
    previous: np.ndarray
    following: np.ndarray
    emotion: np.ndarray
    stand_in: np.ndarray

    @property
    def count(self) -> int:
        return len(self.phoneme)


def collect_occurrences(corpus: Any) -> tuple[Occurrences, np.ndarray]:
    """The occurrences of ``corpus`` and its frames stacked (n_frames, n_channels)."""
    columns: dict[str, list[Any]] = {name: [] for name in Occurrences.__dataclass_fields__}
    del columns["fps"]
    stacked, first = [], 0
    for utterance in corpus.utterances:
        phones = utterance.phones
        labels = [PHONEME_INDEX[span.phoneme] for span in phones]
        silence = PHONEME_INDEX[SILENCE]
        for index, span in enumerate(phones):
            columns["first_row"].append(first)
            columns["rows"].append(len(utterance.frames))
            columns["start"].append(span.start)
            columns["duration"].append(span.end - span.start)
            columns["phoneme"].append(labels[index])
            columns["previous"].append(labels[index - 1] if index > 0 else silence)
            columns["following"].append(labels[index + 1] if index + 1 < len(phones) else silence)
            columns["emotion"].append(EMOTION_INDEX.get(utterance.emotion, 0))
        stacked.append(np.asarray(utterance.frames, dtype=np.float64))
        first += len(utterance.frames)
    if not columns["start"]:
        raise CorpusError("the corpus has no phoneme spans to learn modes from")
    kinds = {"start": np.float64, "duration": np.float64}
    arrays = {
        name: np.asarray(values, dtype=kinds.get(name, np.int64))
        for name, values in columns.items()
    }
    return Occurrences(fps=float(corpus.fps), **arrays), np.concatenate(stacked)


def resample(occurrences: Occurrences, frames: np.ndarray, points: int) -> np.ndarray:
    """Each occurrence's curve at ``points`` local times in [0, 1], flattened (n, points * C)."""
    local = np.linspace(0.0, 1.0, points)
    curves = np.empty((len(occurrences.start), points * frames.shape[1]))
    splines: dict[int, CubicSpline | None] = {}
    for index in range(len(occurrences.start)):
        first, rows = int(occurrences.first_row[index]), int(occurrences.rows[index])
        if first not in splines:
            block = frames[first : first + rows]
            times = np.arange(rows) / occurrences.fps
            splines[first] = CubicSpline(times, block, axis=0) if rows >= 2 else None
        spline = splines[first]
        times = occurrences.start[index] + occurrences.duration[index] * local
        if spline is None:
            sampled = np.repeat(frames[first : first + 1], points, axis=0)
        else:
            sampled = spline(np.clip(times, 0.0, (rows - 1) / occurrences.fps))
        curves[index] = sampled.ravel()
    return curves


def cluster(curves: np.ndarray, min_occurrences: int) -> np.ndarray:
    """Affinity-propagation labels 0.. of ``curves``, numbered by first appearance."""
    if len(curves) < min_occurrences:
        return np.zeros(len(curves), dtype=np.int64)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        found = AffinityPropagation(random_state=0, damping=0.7, max_iter=400).fit(curves)
    labels = np.asarray(found.labels_)
    if len(found.cluster_centers_indices_) == 0 or (labels < 0).any():
        return np.zeros(len(curves), dtype=np.int64)
    _, first_seen = np.unique(labels, return_index=True)
    order = np.argsort(np.argsort(first_seen))
    return np.asarray(order[np.searchsorted(np.unique(labels), labels)], dtype=np.int64)


def assign_modes(
    occurrences: Occurrences, curves: np.ndarray, min_occurrences: int
) -> tuple[Modes, np.ndarray]:
    """Cluster each phoneme's occurrences; the modes and each occurrence's mode index."""
    mode_of = np.empty(len(curves), dtype=np.int64)
    phoneme_of_mode: list[int] = []
    offsets = [0]
    for phoneme in range(len(PHONEMES)):
        members = np.flatnonzero(occurrences.phoneme == phoneme)
        if len(members):
            labels = cluster(curves[members], min_occurrences)
            mode_of[members] = len(phoneme_of_mode) + labels
            phoneme_of_mode.extend([phoneme] * (int(labels.max()) + 1))
        offsets.append(len(phoneme_of_mode))
    n_modes = len(phoneme_of_mode)
    counts = {
        "previous": (occurrences.previous, len(PHONEMES)),
        "following": (occurrences.following, len(PHONEMES)),
        "emotion": (occurrences.emotion, len(EMOTIONS)),
    }
    tables = {}
    for name, (context, width) in counts.items():
        table = np.zeros((n_modes, width), dtype=np.int64)
        np.add.at(table, (mode_of, context), 1)
        tables[name] = table
    offsets_array = np.asarray(offsets, dtype=np.int64)
    modes = Modes(
        phoneme=np.asarray(phoneme_of_mode, dtype=np.int64),
        offsets=offsets_array,
        stand_in=stand_ins(offsets_array),
        **tables,
    )
    return modes, mode_of


def stand_ins(offsets: np.ndarray) -> np.ndarray:
    """For each phoneme, itself if it has modes, else a seen phoneme of its viseme class
    (oculus15), else silence, else the phoneme with the most modes."""
    scheme = get_scheme("oculus15")
    n_modes = np.diff(offsets)
    if not n_modes.any():
        raise CorpusError("the corpus has no phoneme spans to learn modes from")
    silence = PHONEME_INDEX[SILENCE]
    last_resort = silence if n_modes[silence] else int(np.argmax(n_modes))
    result = np.empty(len(PHONEMES), dtype=np.int64)
    for phoneme, label in enumerate(PHONEMES):
        viseme = scheme.viseme_of(label)
        same = [
            p
            for p, other in enumerate(PHONEMES)
            if n_modes[p] and scheme.viseme_of(other) == viseme
        ]
        result[phoneme] = phoneme if n_modes[phoneme] else (same[0] if same else last_resort)
    return result
