"""α1..α6 by cross-validation (§VI-D): least per-frame error on held-out training lines.

Method. The training utterances are split: every ``VALIDATION_STEP``th one (at
most ``MAX_VALIDATION``) is held out for validation and the database is built
from the rest. For weights α, each validation line is synthesized from its own
phones and emotion (the full search, then post-processing at its frame times)
and compared with its recording: Err_i is the mean squared channel error per
frame and channel (Eq. 13), and the score is Σ_i Err_i (Eq. 12). The paper runs
gradient descent from hundreds of random starts; the score is piecewise
constant in α (a path changes only at discrete α), so each start here runs a
compass search instead, the derivative-free descent: step each log α up and
down, keep any improvement, halve the step when none helps. Starts: the
defaults, then random log-uniform points in ``BOUNDS``; the best α of all
starts wins. α5 and α6 are searched from 20 up: a wrong phoneme or emotion
then costs more than most joins, which is what lets the fast search prune
them (``search``), and what CV chose anyway when it could go lower. The
number of scores is fixed (``evaluations``), so training time is bounded and
the result is deterministic for a seed.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

BOUNDS = np.log(
    np.array([[0.01, 10.0], [0.001, 10.0], [0.01, 100.0], [0.01, 0.99], [0.1, 100.0], [0.1, 100.0]])
)
DEFAULTS = np.array([1.0, 0.05, 1.0, 0.5, 50.0, 50.0])
VALIDATION_STEP = 5
MAX_VALIDATION = 8
FIRST_STEP = 1.0
LAST_STEP = 0.12


def validation_split(n_utterances: int) -> tuple[list[int], list[int]]:
    """(database, validation) utterance indices; no validation below two utterances."""
    if n_utterances < 2:
        return list(range(n_utterances)), []
    chosen = list(range(VALIDATION_STEP - 1, n_utterances, VALIDATION_STEP))[:MAX_VALIDATION]
    if not chosen:
        chosen = [n_utterances - 1]
    held = set(chosen)
    return [i for i in range(n_utterances) if i not in held], chosen


@dataclass(frozen=True)
class WeightSearch:
    """The chosen α, its score, the score of the defaults and the scores evaluated."""

    alphas: np.ndarray
    score: float
    default_score: float
    evaluations: int


def search_weights(
    score: Callable[[np.ndarray], float], evaluations: int, restarts: int, seed: int
) -> WeightSearch:
    """Compass search in log α from the defaults and ``restarts`` − 1 random starts."""
    rng = np.random.default_rng(seed)
    starts = [np.log(DEFAULTS)] + [
        rng.uniform(BOUNDS[:, 0], BOUNDS[:, 1]) for _ in range(max(restarts, 1) - 1)
    ]
    per_start = max(evaluations // len(starts), 1)
    spent = 0
    best_x, best = starts[0], np.inf
    default_score = np.inf
    for number, start in enumerate(starts):
        x = np.clip(start, BOUNDS[:, 0], BOUNDS[:, 1])
        value = score(np.exp(x))
        used = 1
        if number == 0:
            default_score = value
        step = FIRST_STEP
        while used < per_start and step >= LAST_STEP:
            improved = False
            for dim in range(len(x)):
                for sign in (1.0, -1.0):
                    if used >= per_start:
                        break
                    trial = x.copy()
                    trial[dim] = np.clip(trial[dim] + sign * step, *BOUNDS[dim])
                    if trial[dim] == x[dim]:
                        continue
                    trial_value = score(np.exp(trial))
                    used += 1
                    if trial_value < value:
                        x, value, improved = trial, trial_value, True
                        break
            if not improved:
                step /= 2.0
        spent += used
        if value < best:
            best_x, best = x, value
    return WeightSearch(np.exp(best_x), float(best), float(default_score), spent)


def frame_error(synthesized: np.ndarray, recorded: np.ndarray) -> float:
    """Eq. 13: the squared error per frame and channel over the common length."""
    count = min(len(synthesized), len(recorded))
    difference = synthesized[:count] - recorded[:count]
    return float(np.mean(difference**2))


def total_error(errors: Sequence[float]) -> float:
    """Eq. 12."""
    return float(np.sum(errors))
