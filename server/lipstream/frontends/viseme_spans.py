"""Viseme-only timings (Azure viseme events, Polly viseme marks) to phoneme spans.

Method: a viseme names a mouth shape that several phonemes share, not a phoneme; each
becomes one representative phoneme of its class (Azure's 22 IDs follow the SAPI viseme
classes, Polly's 17 letters its own), chosen as the class's most frequent English
phoneme, so the engines, which know phonemes, give it that class's mouth. A viseme lasts
until the next one starts; the last one lasts its phoneme's mean duration (duration
model). What is lost: which phoneme of the class was spoken (T, D and N are one Azure
viseme; P, B and M one in both), so whatever an engine does differently for them
(closure length, coarticulation learnt per phoneme) falls back to the representative.
"""

from __future__ import annotations

from collections.abc import Sequence
from types import MappingProxyType

import numpy as np

from ..phonemes import PHONEME_INDEX, SILENCE
from ..tables import pairs
from ..timeline import PhonemeSpan
from .timings import TimedViseme
from .word_durations import WordDurationModel

AZURE_VISEMES = MappingProxyType(
    pairs("""
        0 sil  1 AH  2 AA  3 AO  4 EH  5 ER  6 IY
        7 UW  8 OW  9 AW  10 OY  11 AY  12 HH  13 R
        14 L  15 S  16 SH  17 DH  18 F  19 T  20 K  21 P
    """)
)
"""Azure viseme ID (SAPI classes: 1 æ ə ʌ, 6 j i ɪ, 7 w u, 19 d t n θ, 21 p b m, ...)."""
POLLY_VISEMES = MappingProxyType(
    pairs("""
        sil sil  p P  t T  S SH  T TH  f F  k K
        i IY  r R  s S  u UW  @ AH  a AA  e EH
        E ER  o OW  O AO
    """)
)
"""Polly viseme letter (p: p b m; t: t d; S: ʃ ʒ tʃ dʒ; T: θ ð; k: k g ŋ; ...)."""
TABLES = {"azure": AZURE_VISEMES, "polly": POLLY_VISEMES}


def viseme_spans(
    model: WordDurationModel, visemes: Sequence[TimedViseme], after: float = 0.0
) -> list[PhonemeSpan]:
    """Contiguous spans from ``after`` (the end of earlier input) to the end of the last
    viseme."""
    spans: list[PhonemeSpan] = []
    for index, viseme in enumerate(visemes):
        phoneme = TABLES[viseme.scheme][viseme.viseme]
        if index + 1 < len(visemes):
            end = visemes[index + 1].start
        else:
            end = viseme.start + float(np.exp(model.log_mean_[PHONEME_INDEX[phoneme]]))
        start = viseme.start if spans else after
        if start < viseme.start:
            spans.append(PhonemeSpan(SILENCE, after, viseme.start))
            start = viseme.start
        if end <= start:
            continue
        if spans and spans[-1].phoneme == phoneme:
            spans[-1] = PhonemeSpan(phoneme, spans[-1].start, end)
        else:
            spans.append(PhonemeSpan(phoneme, start, end))
    return spans
