"""The phoneme onsets that a TTS's viseme events give inside the words it also times.

Method: Azure and Polly send a viseme event per phoneme besides their word boundaries.
Each of a word's phonemes (from the lexicon) is written as the viseme its provider's
documented table gives it (Azure's SAPI classes, Polly's letters), and the word's
phonemes are aligned with the visemes said within the word by a longest common
subsequence: only equal visemes pair, in order, and a viseme the lexicon does not
predict (another pronunciation, a diphthong sent as two visemes) pairs with nothing. A
paired phoneme after the word's first starts when its viseme does; the duration model
shares the time between two such anchors (``spreading``), as it does between the anchors
of character timings (``letter_alignment``). An anchor out of order, or too close to the
previous one to give each phoneme between them time, is dropped.
"""

from __future__ import annotations

from collections.abc import Sequence
from types import MappingProxyType

import numpy as np

from ..phonemes import SILENCE
from .letter_alignment import MIN_ANCHOR_GAP_S
from .timings import TimedViseme

WORD_EDGE_S = 0.001
"""Word and viseme times rounded apart (Polly's are whole ms) are one time within this."""
AZURE_CLASSES = """
0 sil
1 AE AH
2 AA
3 AO
4 EH UH EY
5 ER
6 Y IY IH
7 W UW
8 OW
9 AW
10 OY
11 AY
12 HH
13 R
14 L
15 S Z
16 SH CH JH ZH
17 DH
18 F V
19 D T N TH
20 K G NG
21 P B M
"""
"""Azure's viseme IDs (the SAPI classes of its en-US table) and the phonemes of each."""
POLLY_CLASSES = """
sil sil
p P B M
f F V
T TH DH
t T D N L
k K G NG HH
s S Z
S SH ZH CH JH
r R
i IY IH Y
u UW UH W
@ AH
a AA AE AY AW
e EY EH
E ER
o OW
O AO OY
"""
"""Polly's viseme letters (its US English table) and the phonemes of each."""


def _viseme_of(classes: str) -> MappingProxyType[str, str]:
    return MappingProxyType(
        {
            phoneme: viseme
            for viseme, *phonemes in (line.split() for line in classes.strip().splitlines())
            for phoneme in phonemes
        }
    )


VISEME_OF = {"azure": _viseme_of(AZURE_CLASSES), "polly": _viseme_of(POLLY_CLASSES)}
"""Scheme → phoneme → the viseme that scheme sends for it."""


def paired(expected: Sequence[str], said: Sequence[str]) -> list[tuple[int, int]]:
    """(index in ``expected``, index in ``said``) of a longest common subsequence."""
    lengths = np.zeros((len(expected) + 1, len(said) + 1), dtype=np.int64)
    for i, label in enumerate(expected):
        for j, other in enumerate(said):
            if label == other:
                lengths[i + 1, j + 1] = lengths[i, j] + 1
            else:
                lengths[i + 1, j + 1] = max(lengths[i, j + 1], lengths[i + 1, j])
    pairs: list[tuple[int, int]] = []
    i, j = len(expected), len(said)
    while i and j:
        if expected[i - 1] == said[j - 1] and lengths[i, j] == lengths[i - 1, j - 1] + 1:
            pairs.append((i - 1, j - 1))
            i, j = i - 1, j - 1
        elif lengths[i - 1, j] >= lengths[i, j - 1]:
            i -= 1
        else:
            j -= 1
    return pairs[::-1]


def viseme_onsets(
    visemes: Sequence[TimedViseme], phonemes: Sequence[str], start: float, end: float | None
) -> tuple[float | None, ...]:
    """Each of a word's phonemes' onset from the visemes said within it (the word over
    [``start``, ``end``], ``end`` None: not known), None where the duration model places
    it; () when there is nothing to anchor."""
    if not visemes or len(phonemes) < 2 or SILENCE in phonemes:
        return ()
    table = VISEME_OF[visemes[0].scheme]
    expected = [table.get(phoneme, "") for phoneme in phonemes]
    said = [viseme.viseme for viseme in visemes]
    onsets: list[float | None] = [None] * len(phonemes)
    onsets[0] = start
    last_anchor, last_index = start, 0
    limit = np.inf if end is None else end
    for index, at in paired(expected, said):
        if index == 0:
            continue
        onset = visemes[at].start
        before = MIN_ANCHOR_GAP_S * (index - last_index)
        after = MIN_ANCHOR_GAP_S * (len(phonemes) - index)
        if onset - last_anchor >= before and limit - onset >= after:
            onsets[index] = onset
            last_anchor, last_index = onset, index
    return tuple(onsets) if any(onset is not None for onset in onsets[1:]) else ()


def within_words(
    starts: Sequence[float], ends: Sequence[float | None], visemes: Sequence[TimedViseme]
) -> list[tuple[TimedViseme, ...]]:
    """The visemes said within each word (starts in order): those from the word's start,
    less ``WORD_EDGE_S`` for rounding, to its end (or the next word's start)."""
    ordered = sorted(visemes, key=lambda viseme: viseme.start)
    groups: list[tuple[TimedViseme, ...]] = []
    for index, (start, end) in enumerate(zip(starts, ends)):
        following = starts[index + 1] if index + 1 < len(starts) else np.inf
        stop = min(following, np.inf if end is None else end) - WORD_EDGE_S
        groups.append(
            tuple(
                viseme
                for viseme in ordered
                if start - WORD_EDGE_S <= viseme.start < stop
                and viseme.viseme != VISEME_OF[viseme.scheme][SILENCE]
            )
        )
    return groups
