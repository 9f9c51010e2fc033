"""The /p b m/ closure figures the bench tables share.

A span of /p b m/ counts as closed when the lip aperture (``jawOpen -
mouthClose``) inside it falls below a threshold learned from the training
recordings (``lipstream.evaluation.closure_threshold``); the rate is closed
spans over all such spans of the held-out utterances.
"""

from __future__ import annotations

import numpy as np

from ..corpus import Corpus
from ..evaluation import closure_counts, closure_lags, closure_threshold, lip_aperture


def closure_rate(frames: list[np.ndarray], corpus: Corpus, threshold: float | None) -> float | None:
    """Share of /p b m/ spans of ``corpus`` closed in ``frames`` (one array per utterance);
    None without a threshold, a lip aperture or such spans."""
    if threshold is None:
        return None
    closed = total = 0
    for predicted, utterance in zip(frames, corpus.utterances):
        aperture = lip_aperture(predicted, corpus.channels)
        if aperture is None:
            return None
        got, count = closure_counts(aperture, utterance.phones, corpus.fps, threshold)
        closed, total = closed + got, total + count
    return closed / total if total else None


def learned_threshold(train: Corpus) -> float | None:
    """The closure threshold of ``train``'s recordings; None when its channels have no lip
    aperture."""
    apertures = [(lip_aperture(u.frames, train.channels), u.phones) for u in train.utterances]
    known = [(aperture, phones) for aperture, phones in apertures if aperture is not None]
    if len(known) < len(apertures):
        return None
    return closure_threshold(known, train.fps)


def closure_lag_ms(frames: list[np.ndarray], corpus: Corpus) -> float | None:
    """Mean lag (ms) of the lips' closure in ``frames`` (one array per utterance) behind the
    recordings of ``corpus`` at its /p b m/ spans; None without a lip aperture or such
    spans."""
    lags: list[float] = []
    for predicted, utterance in zip(frames, corpus.utterances):
        synthesized = lip_aperture(predicted, corpus.channels)
        recorded = lip_aperture(utterance.frames, corpus.channels)
        if synthesized is None or recorded is None:
            return None
        lags.extend(closure_lags(recorded, synthesized, utterance.phones, corpus.fps))
    return 1000.0 * float(np.mean(lags)) if lags else None
