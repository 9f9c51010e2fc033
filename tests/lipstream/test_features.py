"""MFCC features: frame placement, streaming equality, rate independence, spectral sense."""

from __future__ import annotations

import numpy as np
import pytest

from lipstream.features import (
    DEFAULT_MFCC,
    _power,
    _windows,
    frame_count,
    frames_covered,
    mel_filterbank,
    mfcc,
)


def _tone(hz: float, seconds: float, rate: int) -> np.ndarray:
    return (0.5 * np.sin(2 * np.pi * hz * np.arange(int(seconds * rate)) / rate)).astype(np.float32)


def test_frames_are_centred_on_a_100_hz_grid() -> None:
    samples = np.zeros(16000, dtype=np.float32)
    samples[8000] = 1.0
    features = mfcc(samples, 16000)
    assert features.shape == (frame_count(1.0), DEFAULT_MFCC.n_coefficients) == (101, 13)
    energy = features[:, 0]
    assert set(np.flatnonzero(energy > energy.min() + 1.0).tolist()) == {49, 50, 51}


def test_frames_computed_piecewise_equal_the_whole_signal() -> None:
    samples = np.random.default_rng(0).normal(size=22050).astype(np.float32)
    whole = mfcc(samples, 22050)
    pieces = np.concatenate(
        [
            mfcc(samples, 22050, 0, 17),
            mfcc(samples, 22050, 17, 60),
            mfcc(samples, 22050, 60, len(whole)),
        ]
    )
    np.testing.assert_array_equal(pieces, whole)


@pytest.mark.parametrize("rate", [8000, 16000, 22050, 44100])
def test_frames_covered_means_the_whole_window_is_inside(rate: int) -> None:
    samples = np.random.default_rng(1).normal(size=rate).astype(np.float32)
    for length in (0, 200, rate // 3, rate - 7):
        covered = frames_covered(length, rate)
        truncated = mfcc(samples[:length], rate, 0, covered + 1)
        full = mfcc(samples, rate, 0, covered + 1)
        np.testing.assert_array_equal(truncated[:covered], full[:covered])
        assert not np.array_equal(truncated[covered], full[covered])


def _voice(f0: float, tilt: float, rate: int) -> np.ndarray:
    """Half a second of a harmonic series on ``f0`` up to 3.9 kHz, amplitudes ``tilt ** k``."""
    times = np.arange(rate // 2) / rate
    harmonics = range(1, int(3900 / f0))
    voice = 0.2 * sum(tilt**k * np.sin(2 * np.pi * f0 * k * times + k) for k in harmonics)
    return np.asarray(voice).astype(np.float32)


@pytest.mark.parametrize("rate", [8000, 22050, 44100])
def test_the_same_sound_gives_close_features_at_any_sample_rate(rate: int) -> None:
    def average(signal: np.ndarray, at: int) -> np.ndarray:
        return np.asarray(mfcc(signal, at)[5:-5].mean(axis=0))

    reference = average(_voice(150.0, 0.8, 16000), 16000)
    resampled = average(_voice(150.0, 0.8, rate), rate)
    other = average(_voice(300.0, 0.6, 16000), 16000)
    assert np.linalg.norm(reference - resampled) < 0.1 * np.linalg.norm(reference - other)


def test_a_tone_lights_the_mel_band_around_its_pitch() -> None:
    filters = mel_filterbank(16000, 512, DEFAULT_MFCC)
    assert filters.shape == (26, 257)
    bins_hz = np.arange(257) * 16000 / 512
    peaks = bins_hz[filters.argmax(axis=1)]
    assert np.all(np.diff(peaks) > 0)
    assert peaks[0] > DEFAULT_MFCC.f_min and peaks[-1] < DEFAULT_MFCC.f_max
    spectrum = np.abs(np.fft.rfft(_tone(1000.0, 0.032, 16000)[:512])) ** 2
    assert abs(peaks[int(np.argmax(filters @ spectrum))] - 1000.0) < 120.0


def test_compiled_windows_and_powers_equal_the_array_expressions() -> None:
    rng = np.random.default_rng(3)
    samples = rng.normal(scale=0.3, size=3000).astype(np.float32)
    starts = np.array([-40, -3, 0, 500, 2950, 2990])  # windows past both ends read zeros
    window = np.hamming(80).astype(np.float32)
    minus_c, scale = np.float32(-0.95), np.float32(1.378)
    padded = _windows(samples, starts, minus_c, scale, window, 96)
    signal = np.concatenate([np.zeros(100, np.float32), samples, np.zeros(200, np.float32)])
    emphasised = (signal[:-1] * minus_c + signal[1:]) * scale  # sample i at index i + 99
    for row, start in enumerate(starts):
        expected = emphasised[start + 99 : start + 179] * window
        np.testing.assert_array_equal(padded[row, :80], expected)
    assert not padded[:, 80:].any()
    spectrum = np.fft.rfft(padded, axis=1).astype(np.complex64)
    expected_power = np.abs(spectrum[:, 2:30].astype(np.complex128)) ** 2
    np.testing.assert_allclose(_power(spectrum, 2, 30), expected_power, rtol=1e-12)
