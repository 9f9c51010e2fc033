"""A search-rung request's spans with the per-span arrays its compiled render reads.

Sketch: ``DamSpans`` is the request's span list (the synthesizer appends to it as
spans arrive) that also keeps, in growing arrays (``engines.growable``), each
span's start, end, phoneme, emotion (the request's when the span names none)
and its mode once chosen (-1 before). ``arrays()`` brings them up to date with
the spans appended since the last call, so a streaming call converts only its
new spans, and hands the kernel their buffers (``kernels.SpanArrays``, no views to
make) while ``rows`` says how many rows hold spans;
the modes chosen by one call are reused by the next: a span's mode depends
only on the spans of its search window (and, at the end of the input, on
there being none after them), which never change.
``owner`` is the owner span of the latest frame rendered, where the next call's
search for its frames' owners starts.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ...phonemes import PHONEME_INDEX
from ...timeline import PhonemeSpan
from ..base import SynthesisRequest
from ..growable import Growable
from .kernels import SpanArrays
from .modes import emotion_index


class DamSpans(list[PhonemeSpan]):
    """The spans of ``request``, with their arrays kept by ``arrays()``; ``resolved`` is the
    request's (search_ahead, tail_ahead)."""

    def __init__(
        self,
        request: SynthesisRequest,
        resolved: tuple[int, int],
        spans: Sequence[PhonemeSpan] = (),
    ) -> None:
        super().__init__(spans)
        self.request = request
        self.resolved = resolved
        self.owner = 0
        self.starts = Growable(np.float64)
        self.ends = Growable(np.float64)
        self.phonemes = Growable(np.int64)
        self.emotions = Growable(np.int64)
        self.modes = Growable(np.int64)
        self._arrays = self._gather()

    @property
    def rows(self) -> int:
        """Spans whose rows ``arrays()`` holds."""
        return self.starts.count

    def _gather(self) -> SpanArrays:
        return SpanArrays(
            self.starts.data,
            self.ends.data,
            self.phonemes.data,
            self.emotions.data,
            self.modes.data,
        )

    def arrays(self) -> SpanArrays:
        """The buffers whose first ``rows`` rows hold the spans' start, end, phoneme, emotion
        and mode, every span appended so far taken in."""
        if self.starts.count == len(self):
            return self._arrays
        for span in self[self.starts.count :]:
            phoneme = PHONEME_INDEX[span.phoneme]
            emotion = emotion_index(self.request, span)
            self.starts.append(span.start)
            self.ends.append(span.end)
            self.phonemes.append(phoneme)
            self.emotions.append(emotion)
            self.modes.append(-1)
        if self._arrays.starts is not self.starts.data:  # the buffers grow together
            self._arrays = self._gather()
        return self._arrays
