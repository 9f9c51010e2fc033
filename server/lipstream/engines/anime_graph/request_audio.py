"""A request's audio as it streams in, and its MFCC frames once they are final.

Sketch: samples accumulate in a buffer that grows geometrically. MFCC frame
k is final once the buffer covers its whole window, or once the input is
finished (the window is then zero-padded exactly as an offline call pads
it), so features computed mid-stream equal the offline ones.
"""

from __future__ import annotations

import math

import numpy as np

from ...audio import Audio
from ...errors import InvalidRequestError
from ...features import MfccConfig, frames_covered, mfcc
from .animes import Curves


class RequestAudio:
    """The audio of one request and its MFCC curve (float32 (n_frames, n_mfcc))."""

    def __init__(self, config: MfccConfig) -> None:
        self.config = config
        self.sample_rate: int | None = None
        self._samples = np.zeros(0, dtype=np.float32)
        self._length = 0
        self._features = np.zeros((0, config.n_coefficients), dtype=np.float32)
        self._covered = (0, 0)
        self._curve: Curves | None = None

    def add(self, audio: Audio) -> None:
        if self.sample_rate is None:
            self.sample_rate = int(audio.sample_rate)
        elif int(audio.sample_rate) != self.sample_rate:
            raise InvalidRequestError(
                f"audio at {audio.sample_rate} Hz follows audio at {self.sample_rate} Hz",
                where="audio",
            )
        samples = np.asarray(audio.samples, dtype=np.float32).ravel()
        needed = self._length + len(samples)
        if needed > len(self._samples):
            grown = np.zeros(max(needed, 2 * len(self._samples)), dtype=np.float32)
            grown[: self._length] = self._samples[: self._length]
            self._samples = grown
        self._samples[self._length : needed] = samples
        self._length = needed

    def _frames_covered(self) -> int:
        """``frames_covered`` of the buffer, remembered until more audio arrives."""
        if self.sample_rate is None:
            return 0
        if self._covered[0] != self._length:
            self._covered = (
                self._length,
                frames_covered(self._length, self.sample_rate, self.config),
            )
        return self._covered[1]

    def _frames_needed(self, until_s: float) -> int:
        return math.ceil(until_s * self.config.rate) + 2

    def ready(self, until_s: float, finished: bool) -> bool:
        """Are the frames describing [0, until_s] final?"""
        if finished:
            return True
        if self.sample_rate is None:
            return False
        return self._frames_covered() >= self._frames_needed(until_s)

    def curves(self, until_s: float) -> Curves:
        """The MFCC curve covering [0, until_s] and every other final frame; call only when
        ``ready``."""
        needed = max(self._frames_needed(until_s), self._frames_covered())
        have = len(self._features)
        if needed > have:
            rate = self.sample_rate or 16000
            fresh = mfcc(self._samples[: self._length], rate, have, needed, self.config)
            self._features = np.concatenate([self._features, fresh])
            self._curve = None
        if self._curve is None:
            self._curve = Curves(
                self._features, np.array([0, len(self._features)]), self.config.rate
            )
        return self._curve
