"""Synthetic corpora for the anime-graph tests: known phonemes, smooth motion, tonal audio.

Each phoneme has a fixed target pose; an utterance's curves pass through the
targets at the span centres (linear interpolation, then a moving average), so
motion depends on context the way coarticulated speech does. Each phoneme's
audio is a tone of its own pitch, so MFCCs tell phonemes apart.
"""

from __future__ import annotations

import numpy as np

from lipstream.audio import Audio
from lipstream.corpus import Corpus, Utterance
from lipstream.timeline import PhonemeSpan

PHONES = ("AA", "B", "M", "IY", "S", "T", "OW", "N")
SAMPLE_RATE = 16000


def phone_pitch(phone: str) -> float:
    return 180.0 + 140.0 * PHONES.index(phone) if phone in PHONES else 0.0


def make_spans(
    rng: np.random.Generator, count: int, phones: tuple[str, ...] = PHONES, start: float = 0.0
) -> list[PhonemeSpan]:
    """``count`` random phones between two silences, 60-160 ms each."""
    labels = ["sil", *rng.choice(phones, size=count).tolist(), "sil"]
    spans: list[PhonemeSpan] = []
    cursor = start
    for label in labels:
        duration = float(np.round(rng.uniform(0.06, 0.16), 4))
        spans.append(PhonemeSpan(label, cursor, cursor + duration))
        cursor += duration
    return spans


def render_motion(
    spans: list[PhonemeSpan], fps: float, targets: dict[str, np.ndarray], rng: np.random.Generator
) -> np.ndarray:
    """Curves (n_frames, n_channels) through each span's target at its centre."""
    n_frames = int(np.floor(spans[-1].end * fps)) + 1
    times = np.arange(n_frames) / fps
    centres = np.array([span.centre for span in spans])
    keys = np.stack(
        [targets[span.phoneme] + rng.normal(0, 0.03, len(targets["sil"])) for span in spans]
    )
    curves = np.stack([np.interp(times, centres, keys[:, c]) for c in range(keys.shape[1])], 1)
    kernel = np.ones(7) / 7.0
    padded = np.pad(curves, ((3, 3), (0, 0)), mode="edge")
    return np.stack(
        [np.convolve(padded[:, c], kernel, "valid") for c in range(curves.shape[1])], axis=1
    ).astype(np.float32)


def render_audio(spans: list[PhonemeSpan], rng: np.random.Generator) -> Audio:
    n_samples = int(np.ceil(spans[-1].end * SAMPLE_RATE))
    samples = rng.normal(0.0, 0.003, n_samples)
    for span in spans:
        first, stop = int(span.start * SAMPLE_RATE), min(n_samples, int(span.end * SAMPLE_RATE))
        pitch = phone_pitch(span.phoneme)
        if pitch:
            t = np.arange(stop - first) / SAMPLE_RATE
            samples[first:stop] += 0.3 * np.sin(2 * np.pi * pitch * t) + 0.1 * np.sin(
                2 * np.pi * 2.7 * pitch * t
            )
    return Audio(samples.astype(np.float32), SAMPLE_RATE)


def make_targets(seed: int, n_channels: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(10_000 + seed)
    return {phone: rng.uniform(0.0, 1.0, n_channels) for phone in ("sil", *PHONES)}


def make_corpus(
    seed: int = 0,
    n_utterances: int = 12,
    length: tuple[int, int] = (6, 14),
    fps: float = 120.0,
    n_channels: int = 6,
    with_audio: bool = True,
    emotions: tuple[str, ...] = ("neutral",),
) -> Corpus:
    """Utterance i has emotion ``emotions[i % len(emotions)]``, which shifts every pose."""
    rng = np.random.default_rng(seed)
    targets = make_targets(seed, n_channels)
    utterances = []
    for index in range(n_utterances):
        spans = make_spans(rng, int(rng.integers(length[0], length[1] + 1)))
        emotion = emotions[index % len(emotions)]
        lift = 0.3 * emotions.index(emotion)
        utterances.append(
            Utterance(
                stem=f"utt{index:03d}",
                frames=render_motion(spans, fps, targets, rng) + lift,
                phones=spans,
                fps=fps,
                audio=render_audio(spans, rng) if with_audio else None,
                emotion=emotion,
            )
        )
    return Corpus(
        name="synthetic",
        fps=fps,
        channels=tuple(f"ch{c}" for c in range(n_channels)),
        utterances=utterances,
    )
