"""Bilabials started before their acoustic onset, against spans moved by hand."""

from __future__ import annotations

import random

import pytest

from lipstream.bilabial_lead import BilabialLead, lead_bilabials
from lipstream.timeline import PhonemeSpan


def _pairs(spans: list[PhonemeSpan]) -> list[tuple[str, float, float]]:
    return [(span.phoneme, span.start, span.end) for span in spans]


def test_each_bilabial_takes_the_lead_from_the_span_before_at_most_half_of_it() -> None:
    spans = [
        PhonemeSpan("M", 0.0, 0.08),
        PhonemeSpan("AA", 0.08, 0.20),
        PhonemeSpan("B", 0.20, 0.28),
        PhonemeSpan("S", 0.28, 0.31),
        PhonemeSpan("P", 0.31, 0.40),
    ]
    moved = lead_bilabials(spans, 0.04)
    # the first M has nothing before it; the B takes 40 ms of the 120 ms AA; the S is 30 ms
    # long, so the P takes only 15 ms of it
    expected = [
        ("M", 0.0, 0.08),
        ("AA", 0.08, 0.16),
        ("B", 0.16, 0.28),
        ("S", 0.28, 0.295),
        ("P", 0.295, 0.40),
    ]
    assert [span.phoneme for span in moved] == [p for p, _, _ in expected]
    assert [(s.start, s.end) for s in moved] == [pytest.approx((a, b)) for _, a, b in expected]


def test_a_bilabial_after_silence_is_led_and_emotions_are_kept() -> None:
    spans = [
        PhonemeSpan("sil", 0.0, 0.30),
        PhonemeSpan("M", 0.30, 0.38, "happy"),
        PhonemeSpan("AY", 0.38, 0.50),
    ]
    moved = lead_bilabials(spans, 0.02)
    assert _pairs(moved) == [
        ("sil", 0.0, pytest.approx(0.28)),
        ("M", pytest.approx(0.28), 0.38),
        ("AY", 0.38, 0.50),
    ]
    assert moved[1].emotion == "happy"


def test_bilabials_in_a_row_each_take_from_the_one_led_before() -> None:
    # N AH M B ER: the M takes 20 ms of the 60 ms AH; the B then sees the M as 20 + 40 ms
    # long and takes its 20 ms as well
    spans = [
        PhonemeSpan("N", 0.0, 0.05),
        PhonemeSpan("AH", 0.05, 0.11),
        PhonemeSpan("M", 0.11, 0.15),
        PhonemeSpan("B", 0.15, 0.19),
        PhonemeSpan("ER", 0.19, 0.30),
    ]
    assert _pairs(lead_bilabials(spans, 0.02)) == [
        ("N", 0.0, 0.05),
        ("AH", 0.05, pytest.approx(0.09)),
        ("M", pytest.approx(0.09), pytest.approx(0.13)),
        ("B", pytest.approx(0.13), 0.19),
        ("ER", 0.19, 0.30),
    ]
    # with a 50 ms lead the M takes half the AH (30 ms): led M 0.08 .. 0.15 minus B's share
    # min(0.05, 0.035) = 35 ms, so the B starts at 0.115
    assert _pairs(lead_bilabials(spans, 0.05))[1:4] == [
        ("AH", 0.05, pytest.approx(0.08)),
        ("M", pytest.approx(0.08), pytest.approx(0.115)),
        ("B", pytest.approx(0.115), 0.19),
    ]


def test_no_lead_and_no_bilabial_leave_the_spans_as_they_are() -> None:
    spans = [PhonemeSpan("AA", 0.0, 0.1), PhonemeSpan("P", 0.1, 0.2), PhonemeSpan("T", 0.2, 0.3)]
    assert lead_bilabials(spans, 0.0) == spans
    plain = [PhonemeSpan("S", 0.0, 0.1), PhonemeSpan("IY", 0.1, 0.3)]
    assert lead_bilabials(plain, 0.05) == plain
    assert lead_bilabials([], 0.05) == []


def test_one_span_at_a_time_gives_the_whole_timeline_and_each_span_once_its_successor_came() -> (
    None
):
    chooser = random.Random(7)
    phonemes = ["P", "B", "M", "AA", "S", "sil", "IY"]
    start, spans = 0.0, []
    for _ in range(60):
        end = start + chooser.uniform(0.01, 0.2)
        spans.append(PhonemeSpan(chooser.choice(phonemes), start, end))
        start = end
    whole = lead_bilabials(spans, 0.03)
    leader, streamed = BilabialLead(0.03), []
    for index, span in enumerate(spans):
        final = leader.push(span)
        if index == 0:
            assert final is None
        else:
            assert final == whole[index - 1]
            streamed.append(final)
    last = leader.close()
    assert last is not None
    assert [*streamed, last] == whole
    assert leader.close() is None
    # the timeline stays contiguous and every span keeps at least half of itself
    for before, after, acoustic in zip(whole, whole[1:], spans, strict=False):
        assert before.end == after.start
        assert before.end - before.start >= 0.5 * (acoustic.end - acoustic.start) - 1e-12
