"""Bilabials started before their acoustic onset: a timeline-to-timeline step.

Sketch: the lips close for /p b m/ (``evaluation.BILABIALS``) well before the sound starts,
so an engine that ties a phoneme's shape to its span can be given an *articulatory* span
instead. Each bilabial span that follows another span starts ``lead_s`` earlier, and the
span before it ends there: the time comes from the preceding span, never more than half of
that span's duration (so a short vowel keeps half of itself). Silence is a span like any
other: the recorded demo character closes its lips during the pause before an
utterance-initial bilabial as early as before one within a phrase (``bench.closure_timing``,
``after_silence``), so a bilabial after silence is led too. A bilabial with no span before
it keeps its start. Spans in a row are taken left to right, each seeing the one before as
already moved, so in /m b/ the /b/ takes at most half of the led /m/.

Span i of the result depends on spans i - 1 .. i + 1 only (its end moves when span i + 1
is a bilabial), so a stream can hand on span i once span i + 1 has come (``BilabialLead``),
and gets the spans ``lead_bilabials`` gives for the whole input.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import replace

from .evaluation import BILABIALS
from .timeline import PhonemeSpan

MAX_LEAD_S = 0.2
"""The largest bilabial lead (s) a model may store."""


def led_pair(
    before: PhonemeSpan, span: PhonemeSpan, lead_s: float
) -> tuple[PhonemeSpan, PhonemeSpan]:
    """``before`` and ``span`` (which follows it) as led: when ``span`` is a bilabial both
    move by min(``lead_s``, half of ``before``), else both as they were."""
    if span.phoneme not in BILABIALS or lead_s <= 0.0:
        return before, span
    shift = min(lead_s, 0.5 * (before.end - before.start))
    return replace(before, end=before.end - shift), replace(span, start=span.start - shift)


class BilabialLead:
    """``lead_bilabials`` one span at a time: ``push`` a span and get the span before it,
    now final; ``close`` gives the last one."""

    def __init__(self, lead_s: float) -> None:
        self.lead_s = lead_s
        self.held: PhonemeSpan | None = None

    def push(self, span: PhonemeSpan) -> PhonemeSpan | None:
        """Take ``span``; the span before it as led (None for the first)."""
        if self.held is None:
            self.held = span
            return None
        final, self.held = led_pair(self.held, span, self.lead_s)
        return final

    def close(self) -> PhonemeSpan | None:
        """The last span taken, which nothing after it moves (None when there is none)."""
        final, self.held = self.held, None
        return final


def lead_bilabials(spans: Iterable[PhonemeSpan], lead_s: float) -> list[PhonemeSpan]:
    """``spans`` (in order) with every bilabial led by up to ``lead_s`` seconds."""
    leader = BilabialLead(lead_s)
    led = [final for span in spans if (final := leader.push(span)) is not None]
    last = leader.close()
    return led if last is None else [*led, last]
