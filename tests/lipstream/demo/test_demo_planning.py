"""Target planning: window model, look-ahead rounding, contact timing, segments."""

from __future__ import annotations

import numpy as np
import pytest

from lipstream.demo.planning import (
    CONTACT_HOLD,
    CONTACT_LEAD_S,
    GESTURE_LEAD_S,
    REQUIRED_SHARE,
    Segment,
    TargetPlan,
    build_segments,
    plan_targets,
    sample_plan,
)
from lipstream.demo.targets import DIPHTHONG_SPLIT, Articulator
from lipstream.errors import InvalidRequestError, UnknownPhonemeError
from lipstream.timeline import PhonemeSpan

HORIZON = 0.3


def _spans(*items: tuple[str, float]) -> list[PhonemeSpan]:
    spans, start = [], 0.0
    for phoneme, length in items:
        spans.append(PhonemeSpan(phoneme, start, start + length))
        start += length
    return spans


def _plan(*items: tuple[str, float]) -> tuple[list[Segment], TargetPlan]:
    spans = _spans(*items)
    segments = build_segments(spans, spans[-1].end, HORIZON)
    return segments, plan_targets(segments, HORIZON)


def test_free_consonant_takes_the_interpolated_path_clipped_to_its_window() -> None:
    # AA (jaw 0.55, lips 0.48) - T (jaw window 0.04..0.14, lips 0.04..0.35) - AA:
    # the straight line between the vowels is 0.55, clipped to the window tops.
    segments, plan = _plan(("sil", 0.1), ("AA", 0.1), ("T", 0.1), ("AA", 0.1), ("sil", 0.1))
    t_index = [segment.phoneme for segment in segments].index("T")
    assert plan.values[t_index, Articulator.JAW] == pytest.approx(0.14)
    assert plan.values[t_index, Articulator.LIPS] == pytest.approx(0.35)
    assert not plan.narrow[t_index, Articulator.JAW]


def test_hh_interpolates_between_its_neighbours() -> None:
    # AA centre 0.15, IY centre 0.35, HH centre 0.25: jaw halfway, (0.55 + 0.17) / 2.
    segments, plan = _plan(("sil", 0.1), ("AA", 0.1), ("HH", 0.1), ("IY", 0.1), ("sil", 0.1))
    hh = [segment.phoneme for segment in segments].index("HH")
    assert plan.values[hh, Articulator.JAW] == pytest.approx(0.36)
    assert plan.values[hh, Articulator.LIPS] == pytest.approx((0.48 + 0.17) / 2)


def test_rounding_is_anticipated_within_the_horizon_only() -> None:
    segments, plan = _plan(("sil", 0.2), ("S", 0.08), ("T", 0.06), ("UW", 0.2), ("sil", 0.3))
    labels = [segment.phoneme for segment in segments]
    s_index, t_index = labels.index("S"), labels.index("T")
    assert plan.values[s_index, Articulator.ROUND] == pytest.approx(0.9)
    assert plan.values[t_index, Articulator.ROUND] == pytest.approx(0.9)
    assert plan.values[0, Articulator.ROUND] == 0.0  # the pause starts 0.34 s before UW


def test_long_pause_prepares_rounding_only_in_its_tail() -> None:
    # A pause longer than twice the horizon is split 0.3 s before its end.
    segments, plan = _plan(("sil", 0.8), ("UW", 0.2), ("sil", 0.1))
    assert [segment.phoneme for segment in segments] == ["sil", "sil", "UW", "sil"]
    assert segments[1].start == pytest.approx(0.5)
    assert plan.values[0, Articulator.ROUND] == 0.0
    assert plan.values[1, Articulator.ROUND] == pytest.approx(0.9)


def test_spread_vowel_blocks_rounding_and_windows_clip_the_look_ahead() -> None:
    _, before_iy = _plan(("sil", 0.1), ("S", 0.08), ("T", 0.06), ("IY", 0.2), ("sil", 0.1))
    assert before_iy.values[1, Articulator.ROUND] == 0.0
    assert before_iy.values[1, Articulator.SPREAD] == pytest.approx(0.55)
    # SH is partly rounded: window 0.35..0.7 clips 0.9 (before UW) and 0 (before IY).
    _, sh_uw = _plan(("sil", 0.1), ("SH", 0.1), ("UW", 0.2), ("sil", 0.1))
    _, sh_iy = _plan(("sil", 0.1), ("SH", 0.1), ("IY", 0.2), ("sil", 0.1))
    assert sh_uw.values[1, Articulator.ROUND] == pytest.approx(0.7)
    assert sh_iy.values[1, Articulator.ROUND] == pytest.approx(0.35)


def test_rounding_beyond_the_horizon_relaxes_to_neutral() -> None:
    # Four free consonants of 0.1 s: the first starts 0.4 s before UW.
    _, plan = _plan(
        ("AA", 0.1), ("S", 0.1), ("T", 0.1), ("K", 0.1), ("S", 0.1), ("UW", 0.2), ("sil", 0.1)
    )
    rounding = plan.values[:, Articulator.ROUND]
    assert rounding[1] == 0.0  # 0.4 s ahead: beyond 0.3 s
    assert rounding[2] == pytest.approx(0.9)  # 0.3 s ahead
    assert rounding[4] == pytest.approx(0.9)


def test_onsets_lead_the_sound_but_keep_requirements_and_hold_contacts() -> None:
    # sil 0-0.2, AE 0.2-0.3, P 0.3-0.35, AE 0.35-0.45, sil 0.45-0.65.
    segments, plan = _plan(("sil", 0.2), ("AE", 0.1), ("P", 0.05), ("AE", 0.1), ("sil", 0.2))
    assert [segment.phoneme for segment in segments] == ["sil", "AE", "P", "AE", "sil"]
    assert plan.contact.tolist() == [False, False, True, False, False]
    assert CONTACT_LEAD_S == 0.1 and CONTACT_HOLD == 0.4 and REQUIRED_SHARE == 0.5
    lips, jaw = plan.onsets[:, Articulator.LIPS], plan.onsets[:, Articulator.JAW]
    # Lips head for the closure 100 ms early (0.2), but not before AE's first half: 0.25.
    assert lips[2] == pytest.approx(0.25)
    # Jaw: 35 ms lead, 0.265 (AE's first half ended at 0.25).
    assert jaw[2] == pytest.approx(0.3 - GESTURE_LEAD_S[Articulator.JAW])
    # Lips leave the closure only after 40% of it: 0.3 + 0.4 * 0.05 = 0.32, later than
    # the usual 40 ms lead (0.31); the jaw keeps P's narrow window for half of it: 0.325,
    # later than its 35 ms lead (0.315).
    assert lips[3] == pytest.approx(0.32)
    assert jaw[3] == pytest.approx(0.325)
    assert np.all(np.diff(plan.onsets[1:], axis=0) >= 0)
    assert plan.values[2, Articulator.LIPS] == pytest.approx(-0.12)


def test_sample_plan_holds_each_value_from_its_onset() -> None:
    onsets = np.array([[-np.inf] * 5, [0.1] * 5, [0.25] * 5])
    values = np.array([[0.0] * 5, [1.0] * 5, [2.0] * 5])
    times = np.array([0.0, 0.099, 0.1, 0.2, 0.25, 0.4])
    sampled = sample_plan(onsets, values, times)
    np.testing.assert_array_equal(sampled[:, 0], [0.0, 0.0, 1.0, 1.0, 2.0, 2.0])


def test_segments_fill_gaps_and_split_diphthongs() -> None:
    spans = [PhonemeSpan("AY", 0.1, 0.3), PhonemeSpan("T", 0.35, 0.4)]
    segments = build_segments(spans, 0.5, HORIZON)
    labels = [
        (segment.phoneme, round(segment.start, 6), round(segment.end, 6)) for segment in segments
    ]
    middle = round(0.1 + DIPHTHONG_SPLIT * 0.2, 6)
    assert labels == [
        ("sil", 0.0, 0.1),
        ("AY", 0.1, middle),
        ("AY", middle, 0.3),
        ("sil", 0.3, 0.35),
        ("T", 0.35, 0.4),
        ("sil", 0.4, 0.5),
    ]
    assert (
        segments[1].target.windows[Articulator.JAW][0]
        > segments[2].target.windows[Articulator.JAW][0]
    )


def test_unknown_label_and_bad_duration_raise() -> None:
    with pytest.raises(UnknownPhonemeError, match="XX"):
        build_segments([PhonemeSpan("XX", 0.0, 0.1)], 0.2, HORIZON)
    with pytest.raises(InvalidRequestError):
        build_segments([], 0.0, HORIZON)
