"""espeak-ng's IPA phoneme names as IPA proper.

Method: asked for IPA names (``espeakINITIALIZE_PHONEME_IPA``), espeak-ng
writes each phoneme's IPA, except that a phoneme its language file gives no
IPA for keeps parts of its ASCII mnemonic (Mandarin ``s.``, ``ts.h``, ``i.``;
Kyrgyz ``tS``; Icelandic ``l#``). Those parts follow espeak-ng's mnemonic
conventions (docs/phonemes.md of espeak-ng): ``.`` after a letter makes it
retroflex, ``^`` palatal, ``[`` dental, ``h`` after a stop is aspiration,
``#``, ``-`` and a backquote mark variants (dropped), and capitals and
digits are Kirshenbaum letters; ``ng`` (Mandarin ``ong``, ``ing``) is [ŋ], and a doubled letter (Italian ``ss``, Cantonese ``aa``) is long. ``as_ipa`` rewrites them; IPA passes through
unchanged. Mandarin ``i.`` (the vowel of zhi, shi, ri) is written [ɨ], the
usual broad transcription of that apical vowel.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

_RETROFLEX: Mapping[str, str] = MappingProxyType(
    {"s": "ʂ", "z": "ʐ", "t": "ʈ", "d": "ɖ", "n": "ɳ", "l": "ɭ", "r": "ɽ", "i": "ɨ"}
)
_PALATAL: Mapping[str, str] = MappingProxyType({"n": "ɲ", "l": "ʎ"})
_KIRSHENBAUM: Mapping[str, str] = MappingProxyType({
    "A": "ɑ", "E": "ɛ", "I": "ɪ", "O": "ɔ", "U": "ʊ", "V": "ʌ", "N": "ŋ", "S": "ʃ", "Z": "ʒ",
    "T": "θ", "D": "ð", "C": "ç", "X": "χ", "Q": "ɒ", "@": "ə", "3": "ɜ", "0": "ɒ", "?": "ʔ",
    "Φ": "ɸ", "ε": "ɛ", "R": "ʁ", "L": "ɫ", "B": "β", "G": "ɣ", "J": "ɟ", "W": "ʍ",
})  # fmt: skip
_WHOLE: Mapping[str, str] = MappingProxyType({"sx": "ɧ"})  # Swedish sj-sound
_ASPIRATED_AFTER = frozenset("ptkcqbdgʈɖɕʂʃ")
_DROPPED = frozenset("#-`'\",%=;_!|")


def as_ipa(name: str) -> str:
    """``name`` as espeak-ng would have written it had its language file given an IPA name."""
    if name in _WHOLE:
        return _WHOLE[name]
    name = name.replace("ng", "ŋ").replace("nɡ", "ŋ")
    out: list[str] = []
    for index, char in enumerate(name):
        previous = out[-1] if out else ""
        if char == "." and previous in _RETROFLEX:
            out[-1] = _RETROFLEX[previous]
        elif char == "^" and previous in _PALATAL:
            out[-1] = _PALATAL[previous]
        elif char == "[" and previous:
            out.append("\u032a")
        elif char == "h" and index > 0 and previous in _ASPIRATED_AFTER:
            out.append("ʰ")
        elif char == previous and char.isascii() and char.isalpha():
            out.append("ː")
        elif char in _DROPPED:
            continue
        else:
            out.append(_KIRSHENBAUM.get(char, char))
    return "".join(out)
