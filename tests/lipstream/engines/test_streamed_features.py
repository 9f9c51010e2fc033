"""A request's audio reduced to features as it arrives: bounded samples, the offline frames."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from lipstream.audio import Audio
from lipstream.engines.streamed_features import StreamedFeatures
from lipstream.features import DEFAULT_MFCC, mfcc, speech_features

RATE = 192_000
SECONDS = 20
CHUNK = RATE // 2  # 0.5 s, as a client streams it


@pytest.mark.parametrize(
    ("analyse", "width", "lookback"),
    [(mfcc, DEFAULT_MFCC.n_coefficients, 0), (speech_features, 28, 1)],
)
def test_streamed_audio_holds_features_and_a_window_and_gives_the_offline_frames(
    analyse: Callable[..., np.ndarray], width: int, lookback: int
) -> None:
    samples = np.random.default_rng(1).normal(scale=0.1, size=RATE * SECONDS).astype(np.float32)
    stream = StreamedFeatures(DEFAULT_MFCC, width, analyse, lookback)
    held = []
    for first in range(0, len(samples), CHUNK):
        chunk = samples[first : first + CHUNK]
        bound = stream.held_bytes_after(len(chunk), RATE)  # what the server admits on
        stream.add(Audio(chunk, RATE))
        held.append(stream.held_bytes)
        assert held[-1] <= bound
    offline = analyse(samples, RATE)
    streamed = stream.through(len(offline))
    np.testing.assert_array_equal(streamed, offline)
    # The whole audio is 15 MB as float32; the stream holds its features (a buffer at most
    # twice their size) and at most two chunks of samples.
    feature_bytes = offline.nbytes
    assert max(held) <= 2 * feature_bytes + 2 * 4 * CHUNK + 4096
    assert max(held) < samples.nbytes / 5
    assert len(stream.samples.view()) < 4 * CHUNK // 2  # a chunk, not the utterance


def test_frames_describing_a_time_are_ready_once_the_audio_covers_their_windows() -> None:
    rate = 16_000
    samples = np.random.default_rng(2).normal(scale=0.1, size=rate).astype(np.float32)
    width = DEFAULT_MFCC.n_coefficients
    stream = StreamedFeatures(DEFAULT_MFCC, width, mfcc)
    assert not stream.ready(0.0, finished=False)  # no audio yet
    assert stream.ready(0.0, finished=True)
    stream.add(Audio(samples[:4000], rate))  # 0.25 s
    # Frame k is centred at k / 100 s with a 25 ms window: frame 23's ends at 0.2425 s, inside
    # the 0.25 s given, frame 24's at 0.2525 s: 24 frames are final.
    assert stream.covered == 24
    # [0, t] is described by the frames through the one after the first at or past t:
    # 23 frames for t = 0.21 s, 24 for 0.215 s, 25 for 0.225 s.
    assert stream.ready(0.21, finished=False)
    assert stream.ready(0.215, finished=False)
    assert not stream.ready(0.225, finished=False)
    offline = mfcc(samples, rate)
    np.testing.assert_array_equal(stream.describing(0.1), offline[:24])  # every final frame
    stream.add(Audio(samples[4000:], rate))
    described = stream.describing(1.0)  # past the end: frames over zero-padded windows
    assert len(described) == 102
    np.testing.assert_array_equal(described[: len(offline)], offline)
