"""Choosing a damped rung's speed κ on training utterances, for every engine with one.

Method: a damped rung's filter runs at ω = κ / (the phoneme's median duration)
(``durations``), so κ is how many filter time constants fit in a typical span.
κ is the value of ``KAPPAS`` whose rung, synthesized over every
``VALIDATION_STEP``th training utterance (at most ``MAX_VALIDATION`` of them),
has the least squared error against the recorded frames. A causal rung that
follows a raw curve (``dam``, ``cohen-massaro``, ``expressive-dp``) computes each
utterance's curve once and runs only the filter per κ (``best_following_kappa``).
A model stores its κ, and a stored κ outside ``KAPPA_RANGE`` ([0.1, 100]) is refused at
load.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from ..numerics.basis import MotionBasis
from .damped import filter_raw

KAPPAS = (1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0, 12.0, 16.0, 24.0)
KAPPA_RANGE = (0.1, 100.0)
"""A stored κ lies here: a tenth of the least and about four times the most that ``KAPPAS``
offers."""
VALIDATION_STEP = 4
MAX_VALIDATION = 50

RawCurve = tuple[np.ndarray, np.ndarray, np.ndarray]
"""A causal rung's raw curve over an utterance's frames: the curve (frames, components), 1 / the
median duration of the phoneme each frame follows (frames,), and the frame times (s)."""


def validation_utterances(corpus: Any) -> Sequence[Any]:
    """The training utterances κ is chosen on."""
    return list(corpus.utterances[::VALIDATION_STEP][:MAX_VALIDATION])


def best_kappa(synthesize: Callable[[float, Any], np.ndarray], utterances: Sequence[Any]) -> float:
    """The κ of ``KAPPAS`` whose frames ``synthesize(kappa, utterance)`` have the least squared
    error against the utterances' recorded frames (compared over their common length)."""
    errors = []
    for kappa in KAPPAS:
        total = 0.0
        for utterance in utterances:
            frames = synthesize(kappa, utterance)
            count = min(len(frames), len(utterance.frames))
            total += float(np.sum((frames[:count] - utterance.frames[:count]) ** 2))
        errors.append(total)
    return KAPPAS[int(np.argmin(errors))]


def best_following_kappa(
    raw_curve: Callable[[Any], RawCurve], basis: MotionBasis, utterances: Sequence[Any]
) -> float:
    """``best_kappa`` of a causal rung whose filter follows ``raw_curve(utterance)`` at
    ω = κ / the median duration, frames mapped back through ``basis``; each utterance's
    raw curve is computed once, the filter per κ."""
    curves: dict[int, RawCurve] = {}

    def synthesize(kappa: float, utterance: Any) -> np.ndarray:
        key = id(utterance)
        if key not in curves:
            curves[key] = raw_curve(utterance)
        raw, rates, times = curves[key]
        _, values = filter_raw(None, raw, kappa * rates, times)
        return basis.reconstruct(values)

    return best_kappa(synthesize, utterances)
