"""Audio features shared by training and serving: MFCC curves, and MFCC plus log energy
with deltas (``speech_features``).

Sketch: feature frame i is centred at ``i / rate`` seconds. Its window
(25 ms) is cut straight out of the pre-emphasised samples (the first-order
filter is matched to its 16 kHz response at every sample rate), zeros standing in
outside the signal, Hamming-windowed and turned into a power spectrum scaled
as a density (by the window's energy and length), so band energies do not
depend on the sample rate. A mel filterbank fixed in Hz (50 Hz to 4 kHz, so any sample rate of
8 kHz or more gives comparable features) pools the spectrum, and the DCT-II
of the log energies gives the cepstrum; the first ``n_coefficients`` are kept.
All frames are analysed at once (windows cut and weighted in one compiled pass, one rfft);
the window, mel pooling and DCT matrices are cached per sample rate.

Every frame depends only on the samples under its own window, so the frames
of a growing stream equal those of the whole signal once the stream covers
their windows (``frames_covered``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np
from numba import njit
from scipy.fft import dct, next_fast_len, rfft

_LOG_FLOOR = 1e-10
REFERENCE_RATE = 16000.0
"""Sample rate at which the pre-emphasis coefficient is stated; at other rates the filter is
re-derived so that it has the same response in Hz."""


@dataclass(frozen=True)
class MfccConfig:
    """MFCC analysis settings; ``rate`` is feature frames per second."""

    rate: float = 100.0
    window_s: float = 0.025
    n_mels: int = 26
    n_coefficients: int = 13
    f_min: float = 50.0
    f_max: float = 4000.0
    pre_emphasis: float = 0.97


DEFAULT_MFCC = MfccConfig()


def _hz_to_mel(hz: np.ndarray) -> np.ndarray:
    return 2595.0 * np.log10(1.0 + hz / 700.0)


def _mel_to_hz(mel: np.ndarray) -> np.ndarray:
    return 700.0 * (10.0 ** (mel / 2595.0) - 1.0)


@lru_cache(maxsize=16)
def mel_filterbank(sample_rate: int, n_fft: int, config: MfccConfig) -> np.ndarray:
    """Triangular filters, shape (n_mels, n_fft // 2 + 1), over power-spectrum bins."""
    edges_hz = _mel_to_hz(
        np.linspace(
            _hz_to_mel(np.array(config.f_min)),
            _hz_to_mel(np.array(config.f_max)),
            config.n_mels + 2,
        )
    )
    bins_hz = np.arange(n_fft // 2 + 1) * sample_rate / n_fft
    lower, centre, upper = edges_hz[:-2, None], edges_hz[1:-1, None], edges_hz[2:, None]
    rising = (bins_hz[None, :] - lower) / (centre - lower)
    falling = (upper - bins_hz[None, :]) / (upper - centre)
    return np.asarray(np.maximum(0.0, np.minimum(rising, falling)))


@dataclass(frozen=True)
class _Analysis:
    """Everything about the analysis that depends only on the sample rate and config."""

    length: int
    n_fft: int
    window: np.ndarray
    """Hamming window, float32 (length,)."""
    low_bin: int
    high_bin: int
    pooling: np.ndarray
    """Mel filters over bins low_bin..high_bin - 1 scaled to a power density, (bins, n_mels)."""
    cepstral: np.ndarray
    """Orthonormal DCT-II rows kept, (n_mels, n_coefficients)."""


@lru_cache(maxsize=16)
def _analysis(sample_rate: int, config: MfccConfig) -> _Analysis:
    length = _window_length(sample_rate, config)
    n_fft = next_fast_len(length, real=True)
    window = np.hamming(length)
    filters = mel_filterbank(sample_rate, n_fft, config)
    band = np.flatnonzero(filters.any(axis=0))
    low_bin, high_bin = (int(band[0]), int(band[-1]) + 1) if len(band) else (0, 0)
    density = 1.0 / (float(np.sum(window**2)) * n_fft)
    cepstral = dct(np.eye(config.n_mels), type=2, axis=1, norm="ortho")[:, : config.n_coefficients]
    return _Analysis(
        length,
        n_fft,
        window.astype(np.float32),
        low_bin,
        high_bin,
        np.ascontiguousarray(filters[:, low_bin:high_bin].T * density),
        np.ascontiguousarray(cepstral),
    )


def _window_length(sample_rate: int, config: MfccConfig) -> int:
    return max(2, round(config.window_s * sample_rate))


def _window_starts(first: int, stop: int, sample_rate: int, config: MfccConfig) -> np.ndarray:
    centres = np.round(np.arange(first, stop) * (sample_rate / config.rate)).astype(np.int64)
    return centres - _window_length(sample_rate, config) // 2


def first_sample_read(frame: int, sample_rate: int, config: MfccConfig = DEFAULT_MFCC) -> int:
    """The earliest sample frame ``frame``'s analysis reads (its window's first, less the one
    before it that pre-emphasis reads); may be negative."""
    return int(_window_starts(frame, frame + 1, sample_rate, config)[0]) - 1


def frames_covered(n_samples: int, sample_rate: int, config: MfccConfig = DEFAULT_MFCC) -> int:
    """How many leading frames have their whole window inside the first ``n_samples``."""
    length = _window_length(sample_rate, config)

    def fits(frame: int) -> bool:
        return bool(_window_starts(frame, frame + 1, sample_rate, config)[0] + length <= n_samples)

    step = sample_rate / config.rate
    count = max(0, math.floor((n_samples - length + length // 2) / step) + 1)
    while count > 0 and not fits(count - 1):
        count -= 1
    while fits(count):
        count += 1
    return count


def frame_count(duration_s: float, config: MfccConfig = DEFAULT_MFCC) -> int:
    """Frames i with i / rate <= duration_s."""
    return math.floor(duration_s * config.rate + 1e-9) + 1


def mfcc(
    samples: np.ndarray,
    sample_rate: int,
    first: int = 0,
    stop: int | None = None,
    config: MfccConfig = DEFAULT_MFCC,
    offset: int = 0,
) -> np.ndarray:
    """MFCC frames ``first .. stop - 1`` of mono ``samples`` at ``sample_rate`` Hz.

    ``stop`` defaults to the frames up to the signal's duration. Returns float32
    (n_frames, n_coefficients); frame i is centred at i / rate seconds. ``offset`` is the
    signal's sample that ``samples[0]`` is, when only its tail is held: the frames must
    read nothing before it.
    """
    return _analyse(samples, sample_rate, first, stop, config, False, offset)


def speech_features(
    samples: np.ndarray,
    sample_rate: int,
    first: int = 0,
    stop: int | None = None,
    config: MfccConfig = DEFAULT_MFCC,
    offset: int = 0,
) -> np.ndarray:
    """MFCC plus log energy, with their deltas: float32 (n_frames, 2 (n_coefficients + 1)).

    The log energy is that of the pre-emphasised, windowed frame (as a density, like the
    band energies). Deltas are backward differences (frame i minus frame i − 1; zero at
    frame 0), so a frame is final as soon as its own window is, as for ``mfcc``; they read
    frame ``first`` − 1's window too. ``offset`` as for ``mfcc``.
    """
    if stop is None:
        stop = frame_count((offset + len(samples)) / sample_rate, config)
    if stop <= first:
        return np.zeros((0, 2 * (config.n_coefficients + 1)), dtype=np.float32)
    start = max(0, first - 1)
    static = _analyse(samples, sample_rate, start, stop, config, True, offset)
    deltas = np.diff(static, axis=0, prepend=static[:1])
    both = np.concatenate([static, deltas], axis=1)[first - start :]
    return np.ascontiguousarray(both, dtype=np.float32)


def _analyse(
    samples: np.ndarray,
    sample_rate: int,
    first: int,
    stop: int | None,
    config: MfccConfig,
    with_energy: bool,
    offset: int = 0,
) -> np.ndarray:
    width = config.n_coefficients + (1 if with_energy else 0)
    if stop is None:
        stop = frame_count((offset + len(samples)) / sample_rate, config)
    if stop <= first:
        return np.zeros((0, width), dtype=np.float32)
    analysis = _analysis(int(sample_rate), config)
    length = analysis.length
    starts = _window_starts(first, stop, sample_rate, config) - offset
    coefficient = np.float32(config.pre_emphasis ** (REFERENCE_RATE / sample_rate))
    padded = _windows(  # rfft's zero padding past each window
        np.asarray(samples),
        np.asarray(starts, dtype=np.int64),
        -coefficient,
        np.float32(sample_rate / REFERENCE_RATE),
        analysis.window,
        analysis.n_fft,
    )
    windowed = padded[:, :length]
    energy = None
    if with_energy:
        density = 1.0 / (float(np.sum(analysis.window.astype(np.float64) ** 2)) * analysis.n_fft)
        power_sum = np.einsum("ij,ij->i", windowed, windowed, dtype=np.float64)
        energy = np.log(np.maximum(power_sum * density * analysis.n_fft, _LOG_FLOOR))
    spectrum = rfft(padded, axis=1, overwrite_x=True)
    power = _power(spectrum, analysis.low_bin, analysis.high_bin)
    energies = power @ analysis.pooling
    cepstrum = np.log(np.maximum(energies, _LOG_FLOOR)) @ analysis.cepstral
    if energy is not None:
        cepstrum = np.concatenate([cepstrum, energy[:, None]], axis=1)
    return np.ascontiguousarray(cepstrum, dtype=np.float32)


@njit(cache=True)
def _windows(
    samples: np.ndarray,
    starts: np.ndarray,
    minus_coefficient: np.float32,
    scale: np.float32,
    window: np.ndarray,
    n_fft: int,
) -> np.ndarray:
    """Each window of the pre-emphasised signal times the Hamming window, zero-padded to
    ``n_fft``, in float32 (n_windows, n_fft): sample i of the emphasised signal is
    (x[i − 1] · (−c) + x[i]) · scale, zero outside the signal; the same float32 operations
    as the array expressions it replaces, done only where a window needs them."""
    length = window.shape[0]
    count = samples.shape[0]
    zero = np.float32(0.0)
    padded = np.zeros((starts.shape[0], n_fft), dtype=np.float32)
    for row in range(starts.shape[0]):
        for k in range(length):
            at = starts[row] + k
            before = np.float32(samples[at - 1]) if 0 <= at - 1 < count else zero
            current = np.float32(samples[at]) if 0 <= at < count else zero
            emphasised = (before * minus_coefficient + current) * scale
            padded[row, k] = emphasised * window[k]
    return padded


@njit(cache=True)
def _power(spectrum: np.ndarray, low: int, high: int) -> np.ndarray:
    """|X|² in float64 of bins low .. high − 1 of each row of a complex64 spectrum."""
    power = np.empty((spectrum.shape[0], high - low))
    for row in range(spectrum.shape[0]):
        for bin in range(low, high):
            real = np.float64(spectrum[row, bin].real)
            imaginary = np.float64(spectrum[row, bin].imag)
            power[row, bin - low] = real * real + imaginary * imaginary
    return power


@dataclass(frozen=True)
class SpeakerPrior:
    """What a stream's normalization assumes before it has heard anyone: the speech frames'
    ``mean`` and ``variance`` (float64 (width,)) over a training corpus, worth
    ``prior_frames`` frames of the stream's own. A frame counts as speech when its log
    energy (column ``energy_column``) is above ``silence_energy`` and within ``gate_nats``
    of the loudest frame heard so far."""

    mean: np.ndarray
    variance: np.ndarray
    prior_frames: float
    gate_nats: float
    silence_energy: float
    energy_column: int


SPEECH_GATE_NATS = 6.9
"""About 30 dB of power below the loudest frame so far."""
SILENCE_ENERGY = math.log(1e-8)
"""Log energy under which a frame is taken for digital silence (zeros give the log floor)."""
PRIOR_FRAMES = 40.0
VARIANCE_FLOOR = 0.01
"""A stream's variance is kept above this share of the prior's."""


def speech_frames(
    energy: np.ndarray, loudest_before: float, gate_nats: float, silence_energy: float
) -> tuple[np.ndarray, float]:
    """Which frames count as speech (bool (n,)), each judged against the loudest frame up to
    and including it, and the loudest after them."""
    loudest = np.maximum.accumulate(np.concatenate([[loudest_before], energy]))[1:]
    counted = (energy >= loudest - gate_nats) & (energy > silence_energy)
    return counted, float(loudest[-1]) if len(loudest) else loudest_before


def speaker_prior(
    streams: list[np.ndarray],
    energy_column: int,
    prior_frames: float = PRIOR_FRAMES,
    gate_nats: float = SPEECH_GATE_NATS,
    silence_energy: float = SILENCE_ENERGY,
) -> SpeakerPrior:
    """The prior of ``streams`` (each (n, width), one per recording): the pooled mean and
    variance of their speech frames, each stream gated as ``StreamingNormalizer`` gates it."""
    if not prior_frames > 0.0:
        raise ValueError(f"prior_frames must be positive, got {prior_frames!r}")
    chosen = []
    for rows in streams:
        values = np.asarray(rows, dtype=np.float64)
        counted, _ = speech_frames(values[:, energy_column], -math.inf, gate_nats, silence_energy)
        chosen.append(values[counted])
    pooled = np.concatenate(chosen)
    if len(pooled) < 2:
        raise ValueError("a speaker prior needs at least two speech frames")
    return SpeakerPrior(
        pooled.mean(axis=0),
        pooled.var(axis=0),
        float(prior_frames),
        float(gate_nats),
        float(silence_energy),
        int(energy_column),
    )


class StreamingNormalizer:
    """Per-stream mean and variance normalization, causal: frame t becomes
    (x_t − m_t) / s_t, m_t and s_t² the mean and variance of the speech frames up to and
    including t pooled with the prior's ``prior_frames`` frames. ``apply`` takes the frames
    in order, in any chunking; the sums run through one ``np.cumsum`` carried from chunk
    to chunk, so every chunking gives the same numbers bit for bit."""

    def __init__(self, prior: SpeakerPrior) -> None:
        self.prior = prior
        weight = prior.prior_frames
        self.sums = weight * prior.mean
        self.squares = weight * (prior.variance + prior.mean**2)
        self.count = weight
        self.loudest = -math.inf
        self.floor = VARIANCE_FLOOR * prior.variance

    def apply(self, rows: np.ndarray) -> np.ndarray:
        """The next frames (n, width), normalized: float32 (n, width)."""
        values = np.asarray(rows, dtype=np.float64)
        if len(values) == 0:
            return np.zeros(values.shape, dtype=np.float32)
        prior = self.prior
        counted, self.loudest = speech_frames(
            values[:, prior.energy_column], self.loudest, prior.gate_nats, prior.silence_energy
        )
        weight = counted.astype(np.float64)
        kept = values * weight[:, None]
        sums = np.cumsum(np.concatenate([self.sums[None], kept]), axis=0)[1:]
        squares = np.cumsum(np.concatenate([self.squares[None], kept * values]), axis=0)[1:]
        count = np.cumsum(np.concatenate([[self.count], weight]))[1:, None]
        mean = sums / count
        variance = np.maximum(squares / count - mean**2, self.floor)
        self.sums, self.squares, self.count = sums[-1], squares[-1], float(count[-1, 0])
        return np.asarray((values - mean) / np.sqrt(variance), dtype=np.float32)


WARPS: tuple[float, ...] = (0.88, 0.94, 1.0, 1.06, 1.12)
"""Vocal-tract-length warps tried by ``most_likely_warp``: formants about 12% lower to 12%
higher than the model's voices."""


def warped(config: MfccConfig, warp: float) -> MfccConfig:
    """``config`` with its filterbank's band [f_min, f_max] moved by the factor ``warp``
    (its filters stay mel-spaced inside it): a voice whose formants sit ``warp`` times
    higher than another's gives, analysed so, about the other's features."""
    return replace(config, f_min=config.f_min * warp, f_max=config.f_max * warp)


def most_likely_warp(
    samples: np.ndarray,
    sample_rate: int,
    config: MfccConfig,
    log_likelihood: Callable[[np.ndarray], np.ndarray],
    warps: Sequence[float] = WARPS,
    analyse: Callable[..., np.ndarray] = mfcc,
) -> float:
    """The warp in ``warps`` whose frames of ``samples`` (``analyse``: ``mfcc`` or
    ``speech_features``) score highest in total under ``log_likelihood`` (frames (n, width)
    -> (n,)); ties go to the first."""
    totals = [
        float(np.sum(log_likelihood(analyse(samples, sample_rate, config=warped(config, warp)))))
        for warp in warps
    ]
    return float(warps[int(np.argmax(totals))])
