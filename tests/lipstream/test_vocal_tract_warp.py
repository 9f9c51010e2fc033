"""Vocal-tract-length warping: the warp picked by maximum likelihood is the one a
synthetic voice's formants were scaled by."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
from scipy.signal import lfilter

from lipstream.features import DEFAULT_MFCC, WARPS, mfcc, most_likely_warp, warped

RATE = 16_000
VOWELS = ((730, 1090, 2440), (270, 2290, 3010), (300, 870, 2240), (530, 1840, 2480))
"""Peterson & Barney's average male formants of /ɑ i u ɛ/ (Hz)."""


def _vowels(scale: float, pitch_hz: float = 120.0, seconds_each: float = 0.4) -> np.ndarray:
    """A glottal pulse train through three resonators per vowel, formants times ``scale``."""
    pieces = []
    for formants in VOWELS:
        n = int(RATE * seconds_each)
        signal = np.zeros(n)
        signal[:: int(RATE / pitch_hz)] = 1.0
        for formant in formants:
            centre, bandwidth = formant * scale, 80.0
            radius = np.exp(-np.pi * bandwidth / RATE)
            angle = 2 * np.pi * centre / RATE
            signal = lfilter([1.0], [1.0, -2 * radius * np.cos(angle), radius**2], signal)
        pieces.append(signal / np.abs(signal).max())
    return (0.3 * np.concatenate(pieces)).astype(np.float32)


def _vowel_gaussians(frames: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    """Each frame scored by the best of one diagonal Gaussian per vowel (the middle of its
    stretch), over the spectral shape (c1 on)."""
    each = np.array_split(frames[:, 1:].astype(np.float64), len(VOWELS))
    middles = [vowel[len(vowel) // 4 : 3 * len(vowel) // 4] for vowel in each]
    means = np.array([middle.mean(axis=0) for middle in middles])
    variances = np.array([middle.var(axis=0) for middle in middles]) + 0.05

    def log_likelihood(rows: np.ndarray) -> np.ndarray:
        centred = rows[:, None, 1:].astype(np.float64) - means[None]
        scores = -0.5 * np.sum(centred**2 / variances + np.log(variances), axis=2)
        return np.asarray(scores.max(axis=1))

    return log_likelihood


@pytest.mark.parametrize("scale", [0.88, 0.94, 1.06, 1.12])
def test_the_most_likely_warp_is_the_factor_the_formants_were_scaled_by(scale: float) -> None:
    reference = _vowel_gaussians(mfcc(_vowels(1.0), RATE))
    shifted = _vowels(scale, pitch_hz=120.0 * scale)
    assert scale in WARPS
    assert most_likely_warp(shifted, RATE, DEFAULT_MFCC, reference) == pytest.approx(scale)


def test_the_unwarped_voice_chooses_no_warp_and_warp_one_is_the_plain_analysis() -> None:
    voice = _vowels(1.0)
    reference = _vowel_gaussians(mfcc(voice, RATE))
    assert most_likely_warp(voice, RATE, DEFAULT_MFCC, reference) == 1.0
    np.testing.assert_array_equal(
        mfcc(voice, RATE, config=warped(DEFAULT_MFCC, 1.0)), mfcc(voice, RATE)
    )
