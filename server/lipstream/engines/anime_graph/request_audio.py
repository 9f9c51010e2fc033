"""A request's audio as it streams in, and its MFCC frames once they are final.

Sketch: each chunk goes to ``StreamedFeatures``, which computes the MFCC frames
whose windows it completes and keeps only the samples later frames read. MFCC
frame k is final once the audio covers its whole window, or once the input is
finished (the window is then zero-padded exactly as an offline call pads it),
so features computed mid-stream equal the offline ones.
"""

from __future__ import annotations

import math

import numpy as np

from ...audio import Audio
from ...features import MfccConfig, mfcc
from ..streamed_features import StreamedFeatures
from .animes import Curves


class RequestAudio:
    """The audio of one request and its MFCC curve (float32 (n_frames, n_mfcc))."""

    def __init__(self, config: MfccConfig) -> None:
        self.config = config
        self.stream = StreamedFeatures(config, config.n_coefficients, mfcc)
        self._curve: Curves | None = None

    @property
    def sample_rate(self) -> int | None:
        return self.stream.sample_rate

    @property
    def held_bytes(self) -> int:
        return self.stream.held_bytes

    def add(self, audio: Audio) -> None:
        before = self.stream.features.count
        self.stream.add(audio)
        if self.stream.features.count != before:
            self._curve = None

    def _frames_needed(self, until_s: float) -> int:
        return math.ceil(until_s * self.config.rate) + 2

    def ready(self, until_s: float, finished: bool) -> bool:
        """Are the frames describing [0, until_s] final?"""
        if finished:
            return True
        if self.stream.sample_rate is None:
            return False
        return self.stream.covered >= self._frames_needed(until_s)

    def curves(self, until_s: float) -> Curves:
        """The MFCC curve covering [0, until_s] and every other final frame; call only when
        ``ready``."""
        stream = self.stream
        needed = max(self._frames_needed(until_s), stream.covered)
        if needed > stream.features.count:
            if stream.sample_rate is None:
                stream.sample_rate = 16000  # no audio came: frames of silence
            stream.through(needed)
            self._curve = None
        if self._curve is None:
            features = stream.features.view()
            self._curve = Curves(features, np.array([0, len(features)]), self.config.rate)
        return self._curve
