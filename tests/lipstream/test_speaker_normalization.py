"""Per-stream speaker normalization: causal running mean and variance against numpy's own
batch figures, the same numbers in every chunking, and the frames it leaves alone."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lipstream.audio import Audio
from lipstream.engines.streamed_features import StreamedFeatures
from lipstream.features import (
    DEFAULT_MFCC,
    SpeakerPrior,
    StreamingNormalizer,
    speaker_prior,
    speech_features,
)

RATE = 16_000
ENERGY = DEFAULT_MFCC.n_coefficients
GATE = 6.9
SILENCE = math.log(1e-8)


def _speech_like(seed: int, seconds: float = 3.0) -> np.ndarray:
    """Noise bursts of changing loudness between stretches of digital silence."""
    rng = np.random.default_rng(seed)
    samples = np.zeros(int(RATE * seconds), dtype=np.float32)
    for start in range(RATE // 4, len(samples) - RATE // 4, RATE // 3):
        burst = rng.normal(scale=rng.uniform(0.01, 0.3), size=RATE // 5)
        samples[start : start + len(burst)] = burst
    return samples


def _prior(width: int, weight: float) -> SpeakerPrior:
    rng = np.random.default_rng(7)
    return SpeakerPrior(
        rng.normal(size=width), rng.uniform(0.5, 2.0, size=width), weight, GATE, SILENCE, ENERGY
    )


def test_streamed_normalization_is_the_batch_mean_and_variance_of_the_speech_so_far() -> None:
    raw = speech_features(_speech_like(1), RATE).astype(np.float64)
    prior = _prior(raw.shape[1], 20.0)
    normalized = StreamingNormalizer(prior).apply(raw)
    energy = raw[:, ENERGY]
    for t in (40, 120, len(raw) - 1):
        loudest = energy[: t + 1].max()
        # Judged as each frame arrives: the loudest frame up to it, not up to t.
        counted = [
            k
            for k in range(t + 1)
            if energy[k] >= energy[: k + 1].max() - GATE and energy[k] > SILENCE
        ]
        assert loudest > SILENCE and len(counted) > 10
        heard = raw[counted]
        w, n = prior.prior_frames, len(heard)
        mean = (w * prior.mean + n * heard.mean(axis=0)) / (w + n)
        second = (w * (prior.variance + prior.mean**2) + n * (heard**2).mean(axis=0)) / (w + n)
        expected = (raw[t] - mean) / np.sqrt(second - mean**2)
        np.testing.assert_allclose(normalized[t], expected, rtol=1e-4, atol=1e-4)


def test_with_a_weightless_prior_the_end_of_a_stream_is_numpys_zscore_of_its_speech() -> None:
    raw = speech_features(_speech_like(2), RATE).astype(np.float64)
    normalized = StreamingNormalizer(_prior(raw.shape[1], 1e-9)).apply(raw)
    energy = raw[:, ENERGY]
    running = np.maximum.accumulate(energy)
    speech = raw[(energy >= running - GATE) & (energy > SILENCE)]
    expected = (raw[-1] - speech.mean(axis=0)) / speech.std(axis=0)
    np.testing.assert_allclose(normalized[-1], expected, rtol=1e-4, atol=1e-4)


@pytest.mark.parametrize("chunk", [1, 7, 160, 997, 4800])
def test_any_chunking_gives_the_same_normalized_frames_bit_for_bit(chunk: int) -> None:
    samples = _speech_like(3)
    prior = _prior(28, 40.0)
    whole = StreamingNormalizer(prior).apply(speech_features(samples, RATE))
    stream = StreamedFeatures(
        DEFAULT_MFCC, 28, speech_features, lookback=1, normalizer=StreamingNormalizer(prior)
    )
    for first in range(0, len(samples), chunk):
        stream.add(Audio(samples[first : first + chunk], RATE))
    np.testing.assert_array_equal(stream.through(len(whole)), whole)


def test_the_prior_pools_the_speech_frames_of_every_stream() -> None:
    streams = [speech_features(_speech_like(seed), RATE) for seed in (4, 5)]
    prior = speaker_prior(streams, ENERGY, 40.0, GATE, SILENCE)
    kept = []
    for rows in streams:
        energy = rows[:, ENERGY].astype(np.float64)
        kept.append(rows[(energy >= np.maximum.accumulate(energy) - GATE) & (energy > SILENCE)])
    pooled = np.concatenate(kept).astype(np.float64)
    np.testing.assert_allclose(prior.mean, pooled.mean(axis=0), rtol=1e-9)
    np.testing.assert_allclose(prior.variance, pooled.var(axis=0), rtol=1e-9)


def test_digital_silence_leaves_the_prior_as_it_is() -> None:
    prior = _prior(28, 40.0)
    silent = speech_features(np.zeros(RATE, np.float32), RATE)
    normalized = StreamingNormalizer(prior).apply(silent)
    np.testing.assert_allclose(
        normalized, (silent - prior.mean) / np.sqrt(prior.variance), rtol=1e-5, atol=1e-5
    )
