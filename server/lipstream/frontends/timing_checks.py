"""Checks every timing format shares: times are numbers, finite and not negative; items
follow each other without overlap; there is something to speak.

Sketch: a format reads each item's raw values through ``seconds`` (scaled from its unit:
seconds, milliseconds, 100-ns ticks) and hands the items, in input order, to
``check_order``. Out of order (an item starting before the previous one started) and
overlapping (starting before the previous one ended, beyond ``OVERLAP_TOLERANCE_S`` of
rounding) are both ``non_monotonic_times``, naming the item; a negative, NaN or infinite
time is ``invalid_times``; no items at all is ``empty_timings``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from lipstream_client.errors import EMPTY_TIMINGS, INVALID_TIMES, NON_MONOTONIC_TIMES

from ..errors import LipstreamError

OVERLAP_TOLERANCE_S = 0.002
"""Overlap forgiven as rounding: TTS engines print times to the millisecond (or coarser)."""


def seconds(value: Any, where: str, unit_s: float = 1.0) -> float:
    """``value`` (a number in units of ``unit_s`` seconds) in seconds; ``invalid_times``
    at ``where`` for anything but a finite, non-negative number."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise LipstreamError(
            f"a time must be a number, got {_shown(value)}", where=where, code=INVALID_TIMES
        )
    scaled = float(value) * unit_s
    if not math.isfinite(scaled):
        raise LipstreamError(
            f"a time must be finite, got {value!r}", where=where, code=INVALID_TIMES
        )
    if scaled < 0:
        raise LipstreamError(
            f"a time must not be negative, got {value!r}", where=where, code=INVALID_TIMES
        )
    return scaled


def check_span(start: float, end: float, where: str) -> None:
    """``end`` is not before ``start`` (``invalid_times``)."""
    if end < start:
        raise LipstreamError(
            f"ends at {end:.6g} s, before it starts at {start:.6g} s",
            where=where,
            code=INVALID_TIMES,
        )


def check_order(items: Sequence[tuple[float, float | None, str]], what: str) -> None:
    """(start, end or None, where) items in input order follow each other; ``what`` names
    them in the error for an empty list ("words", "characters")."""
    if not items:
        raise LipstreamError(f"there are no {what} to speak", where=what, code=EMPTY_TIMINGS)
    previous_start, previous_end, previous_where = -math.inf, -math.inf, ""
    for start, end, where in items:
        if start < previous_start:
            raise LipstreamError(
                f"out of order: starts at {start:.6g} s, before {previous_where} "
                f"starts at {previous_start:.6g} s",
                where=where,
                code=NON_MONOTONIC_TIMES,
            )
        if start < previous_end - OVERLAP_TOLERANCE_S:
            raise LipstreamError(
                f"overlaps {previous_where}: starts at {start:.6g} s, before it ends at "
                f"{previous_end:.6g} s",
                where=where,
                code=NON_MONOTONIC_TIMES,
            )
        previous_start, previous_where = start, where
        previous_end = start if end is None else end


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."
