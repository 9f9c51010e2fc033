import numpy as np
import pytest

from lipstream.evaluation import (
    CLOSURE_FRACTION,
    closure_centre,
    closure_counts,
    closure_lags,
    closure_threshold,
    lip_aperture,
    rms_error,
)
from lipstream.timeline import PhonemeSpan


def test_rms_error_matches_hand_computation() -> None:
    predicted = np.array([[1.0, 2.0], [3.0, 4.0]])
    recorded = np.array([[1.0, 0.0], [0.0, 4.0]])
    assert rms_error(predicted, recorded) == pytest.approx(np.sqrt((4 + 9) / 4))


def test_aperture_is_jaw_minus_close_and_needs_both_channels() -> None:
    frames = np.array([[0.5, 0.2, 0.9], [0.3, 0.3, 0.0]])
    aperture = lip_aperture(frames, ["jawOpen", "mouthClose", "x"])
    assert aperture is not None
    np.testing.assert_allclose(aperture, [0.3, 0.0])
    assert lip_aperture(frames, ["jawOpen", "x", "y"]) is None


def test_threshold_is_a_fraction_of_median_open_vowel_aperture() -> None:
    fps = 10.0
    aperture = np.array([0.0, 0.4, 0.4, 0.0, 0.6, 0.6, 0.0, 0.2, 0.2, 0.0])
    spans = [PhonemeSpan("AA", 0.1, 0.3), PhonemeSpan("AE", 0.4, 0.6), PhonemeSpan("IY", 0.7, 0.9)]
    assert closure_threshold([(aperture, spans)], fps) == pytest.approx(CLOSURE_FRACTION * 0.5)


def test_closure_counts_only_bilabials_with_frames() -> None:
    fps = 10.0
    aperture = np.array([0.5, 0.01, 0.5, 0.3, 0.3, 0.5])
    spans = [
        PhonemeSpan("M", 0.0, 0.2),
        PhonemeSpan("P", 0.3, 0.5),
        PhonemeSpan("AA", 0.5, 0.6),
        PhonemeSpan("B", 0.55, 0.58),
    ]
    assert closure_counts(aperture, spans, fps, threshold=0.05) == (1, 2)


def test_closure_lags_are_the_shift_of_the_aperture_minimum_at_each_bilabial() -> None:
    fps = 100.0
    times = np.arange(120) / fps
    # recorded lips shut at 0.30 s (in the /b/ span) and 0.80 s (in the /m/ span)
    recorded = np.minimum(np.abs(times - 0.30), np.abs(times - 0.80))
    predicted = np.minimum(np.abs(times - 0.34), np.abs(times - 0.77))  # 40 ms late, 30 early
    spans = [
        PhonemeSpan("AA", 0.0, 0.28),
        PhonemeSpan("B", 0.28, 0.36),
        PhonemeSpan("IY", 0.36, 0.75),
        PhonemeSpan("M", 0.75, 0.85),
        PhonemeSpan("sil", 0.85, 1.2),
    ]
    assert closure_lags(recorded, predicted, spans, fps) == pytest.approx([0.04, -0.03])
    # each minimum is looked for near its span only: mirrored in time, the predicted
    # closures fall at 0.39 s and 0.89 s, each 90 ms after the recorded one nearest it
    mirrored = recorded[::-1].copy()
    assert closure_lags(recorded, mirrored, spans, fps) == pytest.approx([0.09, 0.09])


def test_closure_lags_time_a_held_closure_at_its_centre_not_its_first_frame() -> None:
    fps = 100.0
    times = np.arange(100) / fps
    # recorded lips rest shut from 0.40 to 0.48 s (centre 0.44 s); the prediction dips once,
    # to its lowest at 0.44 s: the same closure, so no lag
    recorded = np.clip(np.abs(times - 0.44) - 0.04, 0.0, None)
    predicted = np.abs(times - 0.44) + 0.01
    spans = [PhonemeSpan("AA", 0.0, 0.4), PhonemeSpan("M", 0.4, 0.48), PhonemeSpan("AA", 0.48, 1.0)]
    assert closure_lags(recorded, predicted, spans, fps) == pytest.approx([0.0])
    # the same prediction 30 ms later is 30 ms late, whatever the recorded plateau's length
    assert closure_lags(recorded, np.roll(predicted, 3), spans, fps) == pytest.approx([0.03])


def test_a_plateau_is_the_run_within_five_percent_of_the_range_above_the_minimum() -> None:
    # range 1.0: frames at or below 0.05 around the minimum (indices 3..6) form the plateau;
    # the low frame at index 9 is not joined to it
    window = np.array([1.0, 0.6, 0.2, 0.05, 0.0, 0.01, 0.04, 0.3, 0.5, 0.02, 0.9])
    assert closure_centre(window) == pytest.approx(4.5)
