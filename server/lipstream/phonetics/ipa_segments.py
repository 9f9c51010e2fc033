"""One IPA label (a phoneme as a TTS or espeak-ng writes it) read into articulatory segments.

Method: the label is decomposed (NFD) and read left to right. A base symbol
(``ipa_features.BASE_SYMBOLS``; a symbol with a cedilla such as ç is looked
up composed) starts a segment; a diacritic or modifier letter after it
changes its features (``DIACRITICS``) or is dropped (``IGNORED_MARKS``); a tie
bar joins the next symbol to it. A modifier letter with no symbol before it
(espeak-ng writes palatalization as a phoneme of its own) is the segment it
is a small copy of. Then, within the label, a stop followed by a fricative is
one affricate at the fricative's place (espeak-ng writes ``ts`` without a tie),
other tied symbols are one segment at the front-most of their places (the one
the face shows), and a repeated segment (a geminate, ``aa``) is one.
A symbol the table does not know raises ``UnreadableSymbol`` naming it.
"""

from __future__ import annotations

import unicodedata
from dataclasses import replace

from .ipa_features import (
    AFFRICATE,
    BASE_SYMBOLS,
    DIACRITICS,
    FRICATIVE,
    IGNORED_MARKS,
    MODIFIER_LETTERS,
    STOP,
    TIES,
    Consonant,
    Segment,
)


class UnreadableSymbol(ValueError):
    """``symbol`` (at ``index`` of the decomposed label) is no IPA symbol the table knows."""

    def __init__(self, label: str, symbol: str, index: int) -> None:
        super().__init__(f"{symbol!r} (U+{ord(symbol):04X}) in {label!r} is not in the IPA table")
        self.label = label
        self.symbol = symbol
        self.index = index


def _is_stop(segment: Segment) -> bool:
    return isinstance(segment, Consonant) and segment.stricture == STOP and not segment.nasal


def _is_plain_fricative(segment: Segment) -> bool:
    return (
        isinstance(segment, Consonant)
        and segment.stricture == FRICATIVE
        and not (segment.rhotic or segment.lateral)
    )


def _affricate(stop: Consonant, fricative: Consonant) -> Consonant:
    return replace(fricative, stricture=AFFRICATE, voiced=stop.voiced)


def _joined(first: Segment, second: Segment) -> Segment:
    if _is_stop(first) and _is_plain_fricative(second):
        assert isinstance(first, Consonant) and isinstance(second, Consonant)
        return _affricate(first, second)
    if isinstance(first, Consonant) and isinstance(second, Consonant):
        return replace(
            first, place=min(first.place, second.place), nasal=first.nasal or second.nasal
        )
    return first


def _symbols(label: str) -> list[tuple[str, int, str]]:
    """(kind, index, symbol) with kind ``base``, ``mark`` or ``tie``; unknown symbols raise."""
    text = unicodedata.normalize("NFD", label)
    read: list[tuple[str, int, str]] = []
    index = 0
    while index < len(text):
        char = text[index]
        composed = unicodedata.normalize("NFC", text[index : index + 2])
        if len(composed) == 1 and composed in BASE_SYMBOLS:
            read.append(("base", index, composed))
            index += 2
            continue
        if char in BASE_SYMBOLS:
            read.append(("base", index, char))
        elif char in TIES:
            read.append(("tie", index, char))
        elif char in DIACRITICS or char in IGNORED_MARKS:
            read.append(("mark", index, char))
        else:
            raise UnreadableSymbol(label, char, index)
        index += 1
    if not any(kind == "base" for kind, _, _ in read):
        letters = [(i, c) for kind, i, c in read if c in MODIFIER_LETTERS]
        if len(letters) == 1:
            index, letter = letters[0]
            return [("base", index, MODIFIER_LETTERS[letter])]
    return read


def ipa_segments(label: str) -> list[Segment]:
    """The segments of ``label`` in order; ``[]`` for a label of marks alone (a bare length
    mark: it lengthens the phoneme before it). Raises ``UnreadableSymbol``."""
    segments: list[Segment] = []
    tied = False
    for kind, _, symbol in _symbols(label):
        if kind == "base":
            segment = BASE_SYMBOLS[symbol]
            if tied and segments:
                segments[-1] = _joined(segments[-1], segment)
            else:
                segments.append(segment)
            tied = False
        elif kind == "tie":
            tied = True
        elif segments and symbol in DIACRITICS:
            segments[-1] = DIACRITICS[symbol](segments[-1])
    return _merged(segments)


def _merged(segments: list[Segment]) -> list[Segment]:
    merged: list[Segment] = []
    for segment in segments:
        if merged and _is_stop(merged[-1]) and _is_plain_fricative(segment):
            previous = merged[-1]
            assert isinstance(previous, Consonant) and isinstance(segment, Consonant)
            merged[-1] = _affricate(previous, segment)
        else:
            merged.append(segment)
    return merged
