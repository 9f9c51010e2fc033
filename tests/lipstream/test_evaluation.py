import numpy as np
import pytest

from lipstream.evaluation import (
    CLOSURE_FRACTION,
    closure_counts,
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
    np.testing.assert_allclose(lip_aperture(frames, ["jawOpen", "mouthClose", "x"]), [0.3, 0.0])
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
