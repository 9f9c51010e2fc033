"""Choosing a damped rung's speed κ on training utterances, for every engine with one.

Method: a damped rung's filter runs at ω = κ / (the phoneme's median duration)
(``durations``), so κ is how many filter time constants fit in a typical span.
κ is the value of ``KAPPAS`` whose rung, synthesized over every
``VALIDATION_STEP``th training utterance (at most ``MAX_VALIDATION`` of them),
has the least squared error against the recorded frames.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

KAPPAS = (1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0, 12.0, 16.0, 24.0)
VALIDATION_STEP = 4
MAX_VALIDATION = 50


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
