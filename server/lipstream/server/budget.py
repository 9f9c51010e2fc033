"""Latency budgets: choosing the fidelity rung whose worst-case latency fits a request.

Method: a request's latency for frame t is the time from receiving the
input that covers t to sending frame t. A rung's frame t is final once the
input covers t + ``lookahead.seconds`` and ``lookahead.phonemes`` further
whole phonemes; with input arriving in real time, and no phoneme longer than
``max_phoneme_ms``, that wait is at most

    lookahead_ms = 1000 * seconds + phonemes * max_phoneme_ms,

to which the rung's compute time is added: the slowest incremental
``feed`` + ``frames`` call measured at start-up (``calibration``), plus a
configured margin. The server takes the first rung of the engine's ladder
(best first) whose worst case is within the budget; without a budget, the
first rung. If none fits, ``min_budget_ms`` is the smallest budget that any
rung meets, rounded up to a whole millisecond.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from lipstream_client.errors import BUDGET_INFEASIBLE

from ..engines.base import CallCost, Rung
from ..errors import LipstreamError

CUSTOM_FIDELITY = "custom"
"""``ready.fidelity`` when the client's options, not a rung, decide the engine's work."""


@dataclass(frozen=True)
class RungEstimate:
    """A rung with its worst-case latency parts and its measured call cost, in milliseconds."""

    rung: Rung
    lookahead_ms: float
    compute_ms: float
    per_phoneme_ms: float
    per_frame_ms: float = 0.0

    @property
    def call_cost(self) -> CallCost:
        return CallCost(self.per_phoneme_ms, self.per_frame_ms)

    @property
    def worst_case_ms(self) -> float:
        return self.lookahead_ms + self.compute_ms


class BudgetInfeasible(LipstreamError):
    """No rung meets the budget; ``min_budget_ms`` is the smallest budget some rung meets."""

    code = BUDGET_INFEASIBLE

    def __init__(self, budget_ms: float, min_budget_ms: int) -> None:
        self.min_budget_ms = min_budget_ms
        super().__init__(
            f"{budget_ms:g} ms is below the {min_budget_ms} ms the fastest rung needs "
            f"(lookahead at real-time input plus compute time)",
            where="latency_budget_ms",
        )


def lookahead_ms(rung: Rung, max_phoneme_ms: float) -> float:
    """The longest time a frame of ``rung`` waits for input arriving in real time (audio
    included: ``start`` does not say whether audio will follow)."""
    lookahead = rung.lookahead
    return (
        1000.0 * (lookahead.seconds + lookahead.audio_seconds) + lookahead.phonemes * max_phoneme_ms
    )


def estimate(
    rung: Rung, max_phoneme_ms: float, compute_ms: float, margin_ms: float, call: CallCost
) -> RungEstimate:
    return RungEstimate(
        rung,
        lookahead_ms(rung, max_phoneme_ms),
        compute_ms + margin_ms,
        call.per_phoneme_ms,
        call.per_frame_ms,
    )


def choose_rung(ladder: Sequence[RungEstimate], budget_ms: float | None) -> RungEstimate:
    """The best rung within ``budget_ms`` (the first rung without a budget).

    BudgetInfeasible when no rung fits; an empty ladder is a programming error.
    """
    if not ladder:
        raise ValueError("an engine must declare at least one fidelity rung")
    if budget_ms is None:
        return ladder[0]
    for candidate in ladder:
        if candidate.worst_case_ms <= budget_ms:
            return candidate
    fastest = min(candidate.worst_case_ms for candidate in ladder)
    raise BudgetInfeasible(budget_ms, math.ceil(fastest))
