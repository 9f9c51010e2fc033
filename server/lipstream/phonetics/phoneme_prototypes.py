"""lipstream's phoneme set described in IPA, so that it can be compared by features.

Method: each of the 39 ARPAbet phonemes is written as the IPA segments of its
General American realizations (the Handbook of the IPA's illustration of
American English): a consonant by one symbol, a monophthong by its usual
qualities (AH is [ʌ] stressed, [ə] reduced, [ɐ] in between), EY and OW also
by their monophthongal onsets [e] and [o] (how English speakers hear those
vowels in other languages), and every diphthong by its onset and offset.
``nearest_phoneme`` parses these with the same reader as its input, so the
phoneme set and the IPA it meets share one feature space.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

CONSONANT_PROTOTYPES: Mapping[str, tuple[str, ...]] = MappingProxyType(
    {
        "P": ("p",),
        "B": ("b",),
        "T": ("t",),
        "D": ("d",),
        "K": ("k",),
        "G": ("ɡ",),
        "CH": ("t͡ʃ",),
        "JH": ("d͡ʒ",),
        "F": ("f",),
        "V": ("v",),
        "TH": ("θ",),
        "DH": ("ð",),
        "S": ("s",),
        "Z": ("z",),
        "SH": ("ʃ",),
        "ZH": ("ʒ",),
        "HH": ("h",),
        "M": ("m",),
        "N": ("n",),
        "NG": ("ŋ",),
        "L": ("l",),
        "R": ("ɹ",),
        "Y": ("j",),
        "W": ("w",),
    }
)

MONOPHTHONG_PROTOTYPES: Mapping[str, tuple[str, ...]] = MappingProxyType(
    {
        "IY": ("i",),
        "IH": ("ɪ",),
        "EH": ("ɛ",),
        "AE": ("æ", "a"),
        "AA": ("ɑ", "ä"),
        "AO": ("ɔ",),
        "AH": ("ʌ", "ə", "ɐ"),
        "UH": ("ʊ",),
        "UW": ("u",),
        "ER": ("ɝ", "ɚ"),
        "EY": ("e",),
        "OW": ("o",),
    }
)

DIPHTHONG_PROTOTYPES: Mapping[str, tuple[str, str]] = MappingProxyType(
    {
        "EY": ("e", "ɪ"),
        "AY": ("a", "ɪ"),
        "AW": ("a", "ʊ"),
        "OY": ("ɔ", "ɪ"),
        "OW": ("o", "ʊ"),
    }
)
