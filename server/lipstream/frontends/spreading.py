"""Words with phonemes and times to contiguous phoneme spans.

Method: each word's time is shared among its phonemes by the duration model
(``word_durations``): first every phoneme gets its mean duration scaled to the word,
which gives each phoneme its local speaking rate; the model then predicts each
phoneme's log duration a_i and spread s_i, and the word's time T is split as
exp(a_i + λ s_i²), with λ found by Newton's method on log Σ exp(a_i + λ s_i²) = log T
(increasing in λ, so it converges in a few steps). Time before the first word and
between words is silence, and so is a word with no phonemes (a dash). A word whose end
is not given (Polly's last word) lasts its phonemes' mean durations at the rate of the
words before it, and ends before the next word starts. A word may fix some of its
phonemes' onsets (character timings, ``letter_alignment``): its time is then cut at those
onsets and each piece is shared among its own phonemes in the same way.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..phonemes import PHONEME_INDEX, PHONEMES, SILENCE
from ..timeline import PhonemeSpan
from .word_durations import WordDurationModel

NEWTON_STEPS = 30
MIN_GAP_S = 1e-4
"""Gaps between words shorter than this are rounding, not pauses."""


@dataclass(frozen=True, slots=True)
class PronouncedWord:
    """A word's canonical phonemes and its time (``end`` None: not given); ``onsets``:
    each phoneme's known onset or None (empty: none known)."""

    phonemes: tuple[str, ...]
    start: float
    end: float | None
    onsets: tuple[float | None, ...] = ()


def spread_words(
    model: WordDurationModel, words: Sequence[PronouncedWord], after: float = 0.0
) -> list[PhonemeSpan]:
    """Contiguous spans from ``after`` (the end of earlier input) to the last word's end."""
    timed = _closed(model, words)
    layout: list[tuple[str, float, float, slice | None, list[Piece]]] = []
    ids: list[int] = []
    first_pass: list[float] = []
    clock = after
    for (phonemes, start, end), word in zip(timed, words):
        if start - clock > MIN_GAP_S:
            layout.append((SILENCE, clock, start, None, []))
            ids.append(PHONEME_INDEX[SILENCE])
            first_pass.append(start - clock)
        else:
            start = clock
        if end - start <= 0 or not phonemes:
            if end > start:
                layout.append((SILENCE, start, end, None, []))
                ids.append(PHONEME_INDEX[SILENCE])
                first_pass.append(end - start)
            clock = max(clock, end)
            continue
        word_ids = [PHONEME_INDEX[phoneme] for phoneme in phonemes]
        means = np.exp(model.log_mean_[word_ids])
        pieces = _pieces(len(word_ids), start, end, word.onsets)
        layout.append(("", start, end, slice(len(ids), len(ids) + len(word_ids)), pieces))
        ids += word_ids
        for first, last, left, right in pieces:
            first_pass += list(means[first:last] * (right - left) / means[first:last].sum())
        clock = end
    id_array = np.array(ids, dtype=np.int64)
    log_first = np.log(np.maximum(np.array(first_pass), 1e-6))
    predicted = model.predict_log(id_array, model.local_rates(id_array, log_first))
    spans: list[PhonemeSpan] = []
    for label, start, end, phonemes_at, pieces in layout:
        if phonemes_at is None:
            _append(spans, PhonemeSpan(label, start, end))
            continue
        at = id_array[phonemes_at]
        word_predicted = predicted[phonemes_at]
        for first, last, left, right in pieces:
            piece = at[first:last]
            durations = share(word_predicted[first:last], model.spread_[piece] ** 2, right - left)
            edges = left + np.concatenate([[0.0], np.cumsum(durations)])
            edges[-1] = right
            for phoneme_id, low, high in zip(piece, edges[:-1], edges[1:]):
                if high > low:
                    _append(spans, PhonemeSpan(PHONEMES[phoneme_id], float(low), float(high)))
    return spans


Piece = tuple[int, int, float, float]
"""Phonemes [first, last) of a word sharing the time [left, right]."""


def _pieces(count: int, start: float, end: float, onsets: Sequence[float | None]) -> list[Piece]:
    """The word cut at each known onset that falls strictly inside the time left for it."""
    cuts = [(0, start)]
    for index in range(1, min(count, len(onsets))):
        onset = onsets[index]
        if onset is not None and cuts[-1][1] < onset < end:
            cuts.append((index, onset))
    cuts.append((count, end))
    return [(first, last, left, right) for (first, left), (last, right) in zip(cuts[:-1], cuts[1:])]


def share(log_durations: np.ndarray, weights: np.ndarray, total: float) -> np.ndarray:
    """Durations exp(a_i + λ w_i) summing to ``total``: Newton on λ in the log domain."""
    target = np.log(total)
    shift = 0.0
    for _ in range(NEWTON_STEPS):
        exponents = log_durations + shift * weights
        peak = exponents.max()
        terms = np.exp(exponents - peak)
        value = peak + np.log(terms.sum()) - target
        if abs(value) < 1e-10:
            break
        slope = float((terms * weights).sum() / terms.sum())
        shift -= value / slope
    durations = np.exp(log_durations + shift * weights)
    return np.asarray(durations * (total / durations.sum()))


def _closed(
    model: WordDurationModel, words: Sequence[PronouncedWord]
) -> list[tuple[tuple[str, ...], float, float]]:
    """Every word with an end: a missing one from mean durations at the running rate."""
    closed: list[tuple[tuple[str, ...], float, float]] = []
    log_rates: list[float] = []
    for index, word in enumerate(words):
        expected = float(np.exp(model.log_mean_[[PHONEME_INDEX[p] for p in word.phonemes]]).sum())
        end = word.end
        if end is None:
            rate = float(np.exp(np.mean(log_rates))) if log_rates else 1.0
            end = word.start + expected * rate
            following = words[index + 1].start if index + 1 < len(words) else None
            if following is not None:
                end = min(end, following)
        elif word.phonemes and end > word.start and expected > 0:
            log_rates.append(float(np.log((end - word.start) / expected)))
        closed.append((word.phonemes, word.start, end))
    return closed


def _append(spans: list[PhonemeSpan], span: PhonemeSpan) -> None:
    if spans and span.phoneme == SILENCE and spans[-1].phoneme == SILENCE:
        spans[-1] = PhonemeSpan(SILENCE, spans[-1].start, span.end)
    else:
        spans.append(span)
