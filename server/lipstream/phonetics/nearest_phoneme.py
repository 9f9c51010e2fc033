"""Any IPA label to lipstream's phonemes: the nearest phoneme by articulatory features.

Method: the label is read into segments (``ipa_segments``); each segment goes
to the phoneme whose prototype (``phoneme_prototypes``) is nearest by a
weighted distance over ``ipa_features`` - consonants to consonants, vowels
to vowels. The weights favour what a face shows: lip rounding and place at
the front of the mouth (``CONSONANT_WEIGHTS``), vowel height (the jaw) over
backness (``VOWEL_WEIGHTS``); the stops, fricatives and nasals keep apart by
manner and nasality. A two-vowel label is one of the phoneme set's
diphthongs when its onset and offset lie within ``DIPHTHONG_TOLERANCE`` of
that diphthong's, else two phonemes. A glottal stop inside a longer label is
a laryngeal gesture the face does not show, so it is dropped there. A
label stands for one phoneme (``nearest_phoneme``) only if it is one segment
or a diphthong.
Nasality and length have no counterpart among the phoneme set's vowels, so
a nasal vowel goes to its oral vowel and length changes nothing.
"""

from __future__ import annotations

from collections.abc import Mapping
from functools import cache, lru_cache
from types import MappingProxyType

from .ipa_features import GLOTTAL, STOP, Consonant, Segment, Vowel
from .ipa_segments import ipa_segments
from .phoneme_prototypes import (
    CONSONANT_PROTOTYPES,
    DIPHTHONG_PROTOTYPES,
    MONOPHTHONG_PROTOTYPES,
)

CONSONANT_WEIGHTS: Mapping[str, float] = MappingProxyType(
    {
        "place": 1.0,
        "stricture": 1.0,
        "voiced": 0.3,
        "nasal": 3.0,
        "lateral": 2.0,
        "rhotic": 2.0,
        "rounded": 1.5,
    }
)
VOWEL_WEIGHTS: Mapping[str, float] = MappingProxyType(
    {
        "height": 2.0,
        "backness": 0.6,
        "rounded": 1.5,
        "rhotic": 2.0,
        "nasal": 0.0,
    }
)
DIPHTHONG_TOLERANCE = 1.2


def consonant_distance(a: Consonant, b: Consonant) -> float:
    """Weighted feature distance between two consonants (0 for equal features)."""
    w = CONSONANT_WEIGHTS
    return (
        w["place"] * abs(a.place - b.place)
        + w["stricture"] * abs(a.stricture - b.stricture)
        + w["voiced"] * (a.voiced != b.voiced)
        + w["nasal"] * (a.nasal != b.nasal)
        + w["lateral"] * (a.lateral != b.lateral)
        + w["rhotic"] * (a.rhotic != b.rhotic)
        + w["rounded"] * abs(a.rounded - b.rounded)
    )


def vowel_distance(a: Vowel, b: Vowel) -> float:
    """Weighted feature distance between two vowels (0 for equal features)."""
    w = VOWEL_WEIGHTS
    return (
        w["height"] * abs(a.height - b.height)
        + w["backness"] * abs(a.backness - b.backness)
        + w["rounded"] * abs(a.rounded - b.rounded)
        + w["rhotic"] * (a.rhotic != b.rhotic)
        + w["nasal"] * (a.nasal != b.nasal)
    )


def _single(ipa: str) -> Segment:
    (segment,) = ipa_segments(ipa)
    return segment


@cache
def _consonants() -> tuple[tuple[str, Consonant], ...]:
    found: list[tuple[str, Consonant]] = []
    for phoneme, prototypes in CONSONANT_PROTOTYPES.items():
        for ipa in prototypes:
            segment = _single(ipa)
            assert isinstance(segment, Consonant), ipa
            found.append((phoneme, segment))
    return tuple(found)


@cache
def _vowels() -> tuple[tuple[str, Vowel], ...]:
    found: list[tuple[str, Vowel]] = []
    for phoneme, prototypes in MONOPHTHONG_PROTOTYPES.items():
        for ipa in prototypes:
            segment = _single(ipa)
            assert isinstance(segment, Vowel), ipa
            found.append((phoneme, segment))
    return tuple(found)


@cache
def _diphthongs() -> tuple[tuple[str, Vowel, Vowel], ...]:
    found: list[tuple[str, Vowel, Vowel]] = []
    for phoneme, (onset, offset) in DIPHTHONG_PROTOTYPES.items():
        first, second = _single(onset), _single(offset)
        assert isinstance(first, Vowel) and isinstance(second, Vowel), phoneme
        found.append((phoneme, first, second))
    return tuple(found)


def nearest_to_segment(segment: Segment) -> str:
    """The phoneme whose prototype is nearest to ``segment`` (first listed on a tie)."""
    if isinstance(segment, Vowel):
        return min(_vowels(), key=lambda item: vowel_distance(segment, item[1]))[0]
    return min(_consonants(), key=lambda item: consonant_distance(segment, item[1]))[0]


def _diphthong(onset: Vowel, offset: Vowel) -> str | None:
    phoneme, distance = min(
        (
            (name, vowel_distance(onset, first) + vowel_distance(offset, second))
            for name, first, second in _diphthongs()
        ),
        key=lambda item: item[1],
    )
    return phoneme if distance <= DIPHTHONG_TOLERANCE else None


def _visible(segments: list[Segment]) -> list[Segment]:
    if len(segments) < 2:
        return segments
    return [
        s
        for s in segments
        if not (isinstance(s, Consonant) and s.place == GLOTTAL and s.stricture == STOP)
    ]


def _as_diphthong(segments: list[Segment]) -> str | None:
    """The diphthong two different vowels make, if they lie near one of the set's."""
    if len(segments) != 2 or segments[0] == segments[1]:
        return None
    onset, offset = segments
    if not (isinstance(onset, Vowel) and isinstance(offset, Vowel)):
        return None
    return _diphthong(onset, offset)


@lru_cache(maxsize=4096)
def phonemes_by_features(label: str) -> tuple[str, ...]:
    """The phonemes for ``label``, one per segment (a diphthong one for two vowels),
    repeats merged; ``()`` for a label of marks alone. Raises ``UnreadableSymbol``."""
    segments = _visible(ipa_segments(label))
    diphthong = _as_diphthong(segments)
    if diphthong is not None:
        return (diphthong,)
    phonemes: list[str] = []
    for segment in segments:
        phoneme = nearest_to_segment(segment)
        if not phonemes or phonemes[-1] != phoneme:
            phonemes.append(phoneme)
    return tuple(phonemes)


def nearest_phoneme(label: str) -> str | None:
    """The phoneme for ``label`` if it is one segment or a diphthong, else None: a label
    that holds several segments is no single phoneme. Raises ``UnreadableSymbol``."""
    segments = _visible(ipa_segments(label))
    if len(segments) == 1:
        return nearest_to_segment(segments[0])
    return _as_diphthong(segments)
