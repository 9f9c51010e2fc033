"""espeak-ng's IPA phoneme names as IPA proper.

Method: asked for IPA names (``espeakINITIALIZE_PHONEME_IPA``), espeak-ng
writes each phoneme's IPA, except that a phoneme its language file gives no
IPA for keeps parts of its ASCII mnemonic (Mandarin ``s.``, ``ts.h``, ``i.``;
Kyrgyz ``tS``; Icelandic ``l#``). Those parts follow espeak-ng's mnemonic
conventions (docs/phonemes.md of espeak-ng): ``.`` after a letter makes it
retroflex, ``^`` palatal, ``[`` dental, ``h`` after a stop is aspiration,
``#``, ``-`` and a backquote mark variants (dropped), and capitals and
digits are Kirshenbaum letters; ``ng`` (Mandarin ``ong``, ``ing``) is [ŋ],
and a doubled letter (Italian ``ss``, Cantonese ``aa``) is long. ``as_ipa``
rewrites them; IPA passes through unchanged. Mandarin ``i.`` (the vowel of
zhi, shi, ri) is written [ɨ], the usual broad transcription of that apical
vowel.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

from ..errors import UnknownPhonemeError, UnmappedPhonemeError
from ..phonemes import SILENCE, ipa_phonemes
from ..tables import pairs

_RETROFLEX: Mapping[str, str] = MappingProxyType(
    {"s": "ʂ", "z": "ʐ", "t": "ʈ", "d": "ɖ", "n": "ɳ", "l": "ɭ", "r": "ɽ", "i": "ɨ"}
)
_PALATAL: Mapping[str, str] = MappingProxyType({"n": "ɲ", "l": "ʎ"})
_KIRSHENBAUM: Mapping[str, str] = MappingProxyType(
    pairs("""
        A ɑ  E ɛ  I ɪ  O ɔ  U ʊ  V ʌ  N ŋ  S ʃ  Z ʒ
        T θ  D ð  C ç  X χ  Q ɒ  @ ə  3 ɜ  0 ɒ  ? ʔ
        Φ ɸ  ε ɛ  R ʁ  L ɫ  B β  G ɣ  J ɟ  W ʍ
    """)
)
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


def is_language_switch(name: str) -> bool:
    """espeak-ng marks a switch of language inside a text (a foreign word) as ``(en)``."""
    return name.startswith("(") and name.endswith(")")


def ipa_event_phonemes(name: str, lang: str, where: str | None = None) -> tuple[str, ...]:
    """The phonemes of one espeak-ng IPA phoneme event of language ``lang``: silence for a
    pause, ``()`` for a language switch or a bare mark (the phoneme before goes on);
    ``UnmappedPhonemeError`` naming the phoneme and the language if no table reads it."""
    if not name or name.startswith("_"):
        return (SILENCE,)
    if is_language_switch(name):
        return ()
    try:
        return ipa_phonemes(as_ipa(name), where)
    except UnknownPhonemeError as exc:
        raise UnmappedPhonemeError(
            f"espeak-ng's phoneme {name!r} in language {lang!r} maps to no phoneme: {exc.message}",
            phoneme=name,
            lang=lang,
            where=where,
        ) from None
