"""A request's audio reduced to its speech features as it arrives, holding a window of it:
the one streaming audio buffer of every engine that listens.

Sketch: feature frame k reads only the samples under its own window (and the one
before it, for pre-emphasis: ``features.first_sample_read``), so when a chunk
arrives every frame whose window it completes (``frames_covered``) is computed
at once, and the samples no frame still to come reads are dropped. A request
then holds its features (13 to 28 numbers per 10 ms) and at most a window and a
chunk of samples, whatever its length and sample rate, where it held every
sample before. Frames computed piecewise equal those of the whole signal
(``features``), so the frames are the same bit for bit. Frames past the
audio's end, whose windows the end zero-pads, are computed only when asked
(``through``), once the input is finished. An engine reads the frames final so far
(``covered``), or asks whether those describing [0, t] are (``ready``, ``describing``).
A ``normalizer`` (``features.StreamingNormalizer``) takes each frame once, in order, as
it is computed, so the normalized frames do not depend on the chunking either.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from ..audio import Audio
from ..errors import InvalidRequestError
from ..features import MfccConfig, StreamingNormalizer, first_sample_read, frames_covered
from .growable import Growable


class StreamedFeatures:
    """The features (float32 (n_frames, ``width``)) of one request's audio, at one sample
    rate. ``analyse(samples, sample_rate, first, stop, config, offset)`` computes frames
    first .. stop − 1 of a signal held from sample ``offset`` on (``features.mfcc``,
    ``features.speech_features``); ``lookback`` is how many frames before frame k it reads
    (1 for the deltas of ``speech_features``); ``normalizer``, if any, normalizes the frames
    as they are computed."""

    def __init__(
        self,
        config: MfccConfig,
        width: int,
        analyse: Callable[..., np.ndarray],
        lookback: int = 0,
        normalizer: StreamingNormalizer | None = None,
    ) -> None:
        self.config = config
        self.analyse = analyse
        self.lookback = lookback
        self.normalizer = normalizer
        self.sample_rate: int | None = None
        self.length = 0
        self.covered = 0
        self.samples = Growable(np.float32)
        self.features = Growable(np.float32, (width,))

    def add(self, audio: Audio) -> None:
        """Take the next chunk: compute the frames it completes, drop the samples no later
        frame reads."""
        rate = int(audio.sample_rate)
        if self.sample_rate is not None and rate != self.sample_rate:
            raise InvalidRequestError(
                f"audio at {rate} Hz follows audio at {self.sample_rate} Hz", where="audio"
            )
        self.sample_rate = rate
        chunk = np.asarray(audio.samples, dtype=np.float32).ravel()
        self.samples.extend(chunk)
        self.length += len(chunk)
        self.covered = frames_covered(self.length, rate, self.config)
        self.through(self.covered)

    @property
    def duration(self) -> float:
        return self.length / self.sample_rate if self.sample_rate else 0.0

    def frames_describing(self, until_s: float) -> int:
        """How many leading frames describe [0, ``until_s``]: through the one after the
        first frame at or past ``until_s``, so that a curve through them interpolates
        anywhere in it."""
        return math.ceil(until_s * self.config.rate) + 2

    def ready(self, until_s: float, finished: bool) -> bool:
        """Are the frames describing [0, ``until_s``] final?"""
        if finished:
            return True
        if self.sample_rate is None:
            return False
        return self.covered >= self.frames_describing(until_s)

    def describing(self, until_s: float) -> np.ndarray:
        """The frames describing [0, ``until_s``] and every other final one (a view, valid
        until the next call); call only once they are ``ready``."""
        return self.through(max(self.frames_describing(until_s), self.covered))

    @property
    def held_bytes(self) -> int:
        """Bytes of the buffers that hold the samples and the features."""
        return int(self.samples.data.nbytes + self.features.data.nbytes)

    def held_bytes_after(self, n_samples: int, sample_rate: int) -> int:
        """A bound on ``held_bytes`` while ``n_samples`` more samples at ``sample_rate`` are
        taken in (each buffer grown as ``Growable`` grows it, before samples are dropped)."""
        samples, features = self.samples, self.features
        new_frames = frames_covered(self.length + n_samples, sample_rate, self.config)
        rows = features.held + max(0, new_frames - features.count)
        return _grown(samples, samples.held + n_samples) + _grown(features, rows)

    def through(self, stop: int) -> np.ndarray:
        """Frames 0 .. ``stop`` − 1 and any others computed (a view, valid until the next
        call); frames past ``covered`` are final only once the input is finished."""
        have = self.features.count
        if stop > have and self.sample_rate is not None:
            samples = self.samples
            fresh = self.analyse(
                samples.view(), self.sample_rate, have, stop, self.config, samples.first
            )
            if self.normalizer is not None:
                fresh = self.normalizer.apply(fresh)
            self.features.extend(fresh)
            next_frame = max(0, self.features.count - self.lookback)
            samples.drop_before(first_sample_read(next_frame, self.sample_rate, self.config))
        return self.features.view()


def _grown(buffer: Growable, rows: int) -> int:
    """Bytes of ``buffer`` once it holds ``rows`` rows."""
    capacity = len(buffer.data)
    if rows > capacity:
        capacity = max(rows, 2 * capacity)
    return capacity * (buffer.data.nbytes // len(buffer.data))
