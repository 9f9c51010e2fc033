"""The closure timing bench on hand-made apertures with known closures."""

from __future__ import annotations

import numpy as np
import pytest

from lipstream.bench.closure_timing import (
    best_lead_ms,
    closure_offsets,
    closure_plateaus,
    grouped,
    plateaus_by_pause,
)
from lipstream.timeline import PhonemeSpan

FPS = 100.0


def _aperture_closed(between_s: tuple[float, float], n_frames: int) -> np.ndarray:
    """Open (1.0) everywhere but shut (0.0) on the frames within ``between_s``."""
    times = np.arange(n_frames) / FPS
    return np.where((times >= between_s[0]) & (times <= between_s[1]), 0.0, 1.0)


def test_offsets_time_each_bilabial_at_its_plateau_centre() -> None:
    spans = [
        PhonemeSpan("AA", 0.0, 0.30),
        PhonemeSpan("B", 0.30, 0.40),
        PhonemeSpan("AA", 0.40, 0.80),
        PhonemeSpan("M", 0.80, 0.90),
        PhonemeSpan("AA", 0.90, 1.20),
    ]
    aperture = _aperture_closed((0.26, 0.30), 120) * _aperture_closed((0.84, 0.90), 120)
    # shut 0.26..0.30 (centre 0.28, 20 ms before B) and 0.84..0.90 (centre 0.87, 70 ms in M)
    assert closure_offsets(aperture, spans, FPS) == pytest.approx([-0.02, 0.07], abs=1e-9)


def test_offsets_skip_a_bilabial_past_the_frames() -> None:
    spans = [PhonemeSpan("AA", 0.0, 0.5), PhonemeSpan("P", 2.0, 2.1)]
    assert closure_offsets(np.ones(50), spans, FPS) == []


def test_grouped_means_per_recorded_offset() -> None:
    recorded = [-0.030, -0.025, -0.010, 0.050]
    predicted = [0.000, -0.005, 0.000, 0.060]
    rows = {row["group"]: row for row in grouped(recorded, predicted)}
    assert rows["< -20"]["count"] == 2
    assert rows["< -20"]["recorded_ms"] == pytest.approx(-27.5)
    assert rows["< -20"]["predicted_ms"] == pytest.approx(-2.5)
    assert rows["< -20"]["lag_ms"] == pytest.approx(25.0)
    assert rows["-20 .. 0"]["lag_ms"] == pytest.approx(10.0)
    assert rows["0 .. 20"]["count"] == 0 and rows["0 .. 20"]["lag_ms"] is None
    assert rows[">= 40"]["lag_ms"] == pytest.approx(10.0)


def test_plateaus_give_each_closure_its_closing_and_release() -> None:
    spans = [
        PhonemeSpan("AA", 0.0, 0.30),
        PhonemeSpan("P", 0.30, 0.40),
        PhonemeSpan("AA", 0.40, 1.00),
    ]
    # shut from 0.25 to 0.42: closes 50 ms before the P, releases 20 ms after it ends
    aperture = _aperture_closed((0.25, 0.42), 100)
    assert closure_plateaus(aperture, spans, FPS) == [pytest.approx((-0.05, 0.12), abs=1e-9)]


def test_plateaus_by_pause_tell_a_bilabial_after_silence_from_one_after_a_phoneme() -> None:
    spans = [
        PhonemeSpan("M", 0.0, 0.10),
        PhonemeSpan("AA", 0.10, 0.30),
        PhonemeSpan("sil", 0.30, 0.50),
        PhonemeSpan("B", 0.50, 0.60),
        PhonemeSpan("AA", 0.60, 0.80),
        PhonemeSpan("P", 0.80, 0.90),
        PhonemeSpan("AA", 0.90, 1.20),
    ]
    shut = [(0.0, 0.05), (0.42, 0.55), (0.83, 0.88)]
    aperture = np.prod([_aperture_closed(edges, 120) for edges in shut], axis=0)
    groups = plateaus_by_pause(aperture, spans, FPS)
    # the line's first M and the B after the pause; the P follows a vowel
    assert groups["silence"] == [
        pytest.approx((0.0, 0.05), abs=1e-9),
        pytest.approx((-0.08, 0.05), abs=1e-9),
    ]
    assert groups["phoneme"] == [pytest.approx((0.03, 0.08), abs=1e-9)]


def test_best_lead_is_the_lag_nearest_zero_without_the_rms_rising() -> None:
    rows = [
        {"lead_ms": 0.0, "lag_ms": 11.0, "rms": 0.0558},
        {"lead_ms": 10.0, "lag_ms": 0.5, "rms": 0.0561},  # nearest 0, but the RMS rose
        {"lead_ms": 20.0, "lag_ms": 2.9, "rms": 0.0556},
        {"lead_ms": 30.0, "lag_ms": -3.3, "rms": 0.0554},
    ]
    assert best_lead_ms(rows) == 20.0
    assert best_lead_ms(rows[:2]) == 0.0


def test_best_lead_also_keeps_the_closures_near_the_character_on_the_real_phones() -> None:
    rows = [
        {"lead_ms": 0.0, "lag_ms": 13.0, "rms": 0.0620, "real_phones_lag_ms": 17.0},
        {"lead_ms": 20.0, "lag_ms": 8.5, "rms": 0.0618, "real_phones_lag_ms": -3.0},
        {"lead_ms": 30.0, "lag_ms": 5.0, "rms": 0.0620, "real_phones_lag_ms": -9.0},
        {"lead_ms": 40.0, "lag_ms": -1.0, "rms": 0.0619, "real_phones_lag_ms": -14.0},
    ]
    # the held-out lines alone pick 40 ms; the larger of the two magnitudes is least at 20
    assert (
        best_lead_ms([{k: v for k, v in r.items() if k != "real_phones_lag_ms"} for r in rows])
        == 40.0
    )
    assert best_lead_ms(rows) == 20.0
