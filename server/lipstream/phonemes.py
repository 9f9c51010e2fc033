"""Canonical phoneme labels and the notations that map onto them.

Method: every label entering lipstream is rewritten to one of 40 canonical
labels, the 39 CMUdict ARPAbet phonemes (upper case, no stress) plus ``sil``.
Each supported notation ("source") is a reader: a table lookup after the
notation's own clean-up (stress digits for ARPAbet, glued stress marks for
espeak-ng, diacritics for IPA). Allophones with no ARPAbet symbol go to the
phoneme whose mouth shape they share (a flap to D, a closure to its stop).
IPA the English table lacks (any language's) goes to the phoneme nearest by
articulatory features (``phonetics.nearest_phoneme``).
``source="auto"`` tries readers in a fixed order and takes the first match.
The tables, with the reasons for every judgement call, are in
``docs/reference/phonemes.md``.
"""

from __future__ import annotations

import re
import unicodedata
from collections.abc import Callable, Iterable, Mapping
from functools import cache, lru_cache
from types import MappingProxyType

from .errors import LipstreamError, UnknownPhonemeError
from .phonetics.ipa_segments import UnreadableSymbol
from .phonetics.nearest_phoneme import nearest_phoneme, phonemes_by_features
from .tables import names, pairs

ARPABET: tuple[str, ...] = names("""
    AA AE AH AO AW AY B CH D DH EH ER EY F G
    HH IH IY JH K L M N NG OW OY P R S SH
    T TH UH UW V W Y Z ZH
""")
SILENCE = "sil"
PHONEMES: tuple[str, ...] = ARPABET + (SILENCE,)
PHONEME_INDEX: dict[str, int] = {p: i for i, p in enumerate(PHONEMES)}

SOURCES: tuple[str, ...] = ("auto", "arpabet", "mfa", "timit", "mocha", "espeak", "ipa", "sampa")
# "request" is what timeline.coerce_spans passes for client-sent labels.
SOURCE_ALIASES: Mapping[str, str] = MappingProxyType({"request": "auto"})

_VOWELS = frozenset(names("AA AE AH AO AW AY EH ER EY IH IY OW OY UH UW AX AXR IX UX"))

# Full ARPAbet (TIMIT-derived) symbols that CMUdict folds away.
_ARPABET_EXTENDED: dict[str, str] = pairs("""
    AX AH  AXR ER  IX IH  UX UW  DX D  NX N
    EL L  EM M  EN N  ENG NG  WH W  Q sil
""")
_ARPABET_TABLE: dict[str, str] = {p: p for p in ARPABET} | _ARPABET_EXTENDED
_ARPABET_SPELLING = re.compile(r"([A-Z]+)([012]?)")

_MFA_SILENCES = frozenset({"", "sil", "sp", "spn"})

# Closures map to their stop: the closure is when a bilabial's lips are shut.
_TIMIT_TABLE: dict[str, str] = {p.lower(): p for p in ARPABET} | pairs("""
    bcl B  dcl D  gcl G  pcl P  tcl T  kcl K
    dx D  nx N  q sil  hv HH
    ax AH  ax-h AH  axr ER  ix IH  ux UW
    em M  en N  eng NG  el L
    h# sil  #h sil  pau sil  epi sil  sil sil
    cl sil  vcl sil
""")

# MOCHA-TIMIT .lab files use the Edinburgh MRPA set (southern British), not TIMIT's.
_MOCHA_TABLE: dict[str, str] = pairs("""
    uh AH  e EH  a AE  o AA  i IH  u UH
    ii IY  uu UW  oo AO  aa AA  @@ ER  @ AH
    ai AY  ei EY  oi OY  au AW  ou OW
    e@ EH  i@ IY  u@ UH
    p P  t T  k K  b B  d D  g G
    s S  z Z  sh SH  zh ZH  f F  v V
    th TH  dh DH  ch CH  jh JH  h HH
    m M  n N  ng NG  l L  y Y  r R  w W
    # sil  sil sil  breath sil
""")

# espeak-ng mnemonics of the English phoneme tables (en, en-us and the other
# en-* variants, with the base tables they inherit), case-sensitive.
_ESPEAK_TABLE: dict[str, str] = (
    # pauses
    pairs("""
        _ sil  _! sil  _: sil  _:: sil  _;_ sil
        _X1 sil  _^_ sil  _| sil  || sil
    """)
    # vowels
    | pairs("""
        @ AH  @- AH  @2 AH  @# AH  @5 UH  @L L
        3 ER  3: ER  IR ER  VR AH  V AH  02 AH  a# AH
        a AE  a/ AE  a2 AE  a#2 AE  aa AE
        A: AA  A@ AA  A# AA  A~ AA  0 AA  0# AA
        O AO  O: AO  O2 AO  O@ AO  o@ AO  O~ AO
        o OW  o: OW  oU OW  oU# OW  OI OY
        E EH  E# EH  E2 EH  e# EH  e@ EH
        e EY  e: EY  eI EY
        I IH  I# IH  I2 IH  I2# IH
        i IY  i: IY  i@ IY  i@3 IY
        U UH  U@ UH  u UW  u: UW
        aI AY  aI2 AY  aI@ AY  aI3 AY  aU AW  aU@ AW
        m- M  n- N  N- NG  l- L
    """)
    # stops and affricates
    | pairs("""
        p P  b B  t T  t# T  t2 T  t[ T  ? T
        d D  d# D  d[ D  * D  ** D
        k K  c K  q K  g G  J G
        tS CH  tS; CH  dZ JH  dZ; JH
    """)
    # fricatives
    | pairs("""
        f F  v V  v# V  B V  T TH  D DH
        s S  s; S  z Z  z# Z  z/2 Z  z; Z
        S SH  S; SH  s. SH  Z ZH  Z; ZH  z. ZH
        h HH  C HH  X HH  #X1 HH  x K  Q G  Q^ G
    """)
    # nasals, liquids, glides
    | pairs("""
        m M  n N  n. N  n^ N  N NG
        l L  l/ L  l/2 L  l/3 L  l^ L  l. L  L L
        L/ L  l# L
        r R  r- R  r/ R  r. R  r" R  R R  R2 R  R3 R
        Q" R  j Y  J^ Y  ; Y  w W  w# W
    """)
)
_ESPEAK_STRESS = "',%="

# IPA as written by MFA's english_mfa models and by espeak-ng --ipa. Keys
# carry no stress, tie bar, length mark or diacritic: those are removed
# before the second lookup (see _ipa_base).
_IPA_TABLE: dict[str, str] = (
    # monophthongs
    pairs("""
        i IY  ɪ IH  ᵻ IH  ɨ IH  e EY  ɛ EH  æ AE  a AE
        ɑ AA  ɒ AA  ɔ AO  o OW  ɵ OW  ʊ UH  u UW  ʉ UW
        ʌ AH  ə AH  ɐ AH  ɘ AH  ɜ ER  ɚ ER  ɝ ER
        ə˞ ER  ɜ˞ ER  əɹ ER  ɜɹ ER
    """)
    # diphthongs and vowel + r
    | pairs("""
        aɪ AY  aj AY  ɑɪ AY  ɑj AY  aɪə AY  aɪɚ AY  aɪɹ AY
        aʊ AW  aw AW  ɑʊ AW  aʊə AW  aʊɚ AW  aʊɹ AW
        eɪ EY  ej EY  ɛɪ EY  oʊ OW  ow OW  əʊ OW  əw OW
        ɔʊ OW  ɔɪ OY  ɔj OY  oɪ OY
        ɪə IY  iə IY  ɪɹ IY  ɪɚ IY  iɹ IY
        ɛə EH  eə EH  ɛɹ EH  eɹ EH  ɛɚ EH
        ʊə UH  ʊɹ UH  ʊɚ UH  uɹ UH
        ɑɹ AA  aɹ AA  ɑɚ AA  ɔɹ AO  oɹ AO  ɔɚ AO  oɚ AO
        ei EY  əɪ AY  əu OW  ʌʊ OW  æʊ AW
        ɑə AA  aa AA  ɔə AO  oə AO  ʉɹ UH  ʌʉ AW
        ʌɹ AH  əl L  ən N  əm M
    """)
    # consonants
    | pairs("""
        p P  b B  t T  d D  k K  ɡ G  g G  c K
        ɟ G  q K  ɢ G  ʔ T  ɾ D  ɾ̃ N
        tʃ CH  ʧ CH  dʒ JH  ʤ JH  tɕ CH  dʑ JH
        f F  v V  ɸ F  β V  ʋ V  θ TH  ð DH
        s S  z Z  ʃ SH  ʒ ZH  ʂ SH  ʐ ZH  ɕ SH  ʑ ZH
        h HH  ɦ HH  ç HH  χ HH  x K  ɣ G  ʁ R
        m M  ɱ M  n N  ɲ N  ɳ N  ŋ NG
        l L  ɫ L  ʎ L  ɭ L  ɬ L  ɹ̩ ER
        ɹ R  r R  ɻ R  ʀ R  j Y  ʝ Y  w W  ʍ W
    """)
)
# English SAMPA as WebMAUS writes it in its MAU tier (British and American
# inventories, with the X-SAMPA spelling r\ and the rhotic `), plus the BAS
# pause and noise markers. Case-sensitive; a length mark ":" is dropped if the
# long form is not listed.
_SAMPA_TABLE: dict[str, str] = (
    # pauses and non-speech
    pairs("""
        <p:> sil  <p> sil  <nib> sil  <usb> sil  <sil> sil
    """)
    # monophthongs
    | pairs("""
        i: IY  i IY  I IH  e EH  E EH  { AE  a AE
        A: AA  A AA  Q AA  O: AO  O AO  o OW  U UH
        u: UW  u UW  V AH  @ AH  3: ER  3 ER  3` ER
        @` ER  r= ER
    """)
    # diphthongs and centring diphthongs
    | pairs("""
        eI EY  aI AY  OI OY  @U OW  oU OW  aU AW
        I@ IY  e@ EH  E@ EH  U@ UH
    """)
    # consonants
    | pairs(r"""
        p P  b B  t T  d D  k K  g G  ? T  4 D
        tS CH  dZ JH  f F  v V  T TH  D DH
        s S  z Z  S SH  Z ZH  h HH  x K  C HH
        m M  n N  N NG  m= M  n= N
        l L  5 L  l= L  r R  r\ R  j Y  w W  W W
    """)
)

_IPA_IGNORED = frozenset("ˈˌ.‿\u0361\u035c")  # stress, syllable break, ties
_IPA_MODIFIERS = frozenset("ːˑ:ʰʲʷˠˤⁿˡʱ")  # length (also ASCII ":") and secondary articulations


def _nfd(text: str) -> str:
    return unicodedata.normalize("NFD", text)


_IPA_LOOKUP: dict[str, str] = {_nfd(key): value for key, value in _IPA_TABLE.items()}


def _read_arpabet(label: str) -> str | None:
    upper = label.upper()
    if upper == "SIL":
        return SILENCE
    match = _ARPABET_SPELLING.fullmatch(upper)
    if match is None:
        return None
    base, stress = match.groups()
    if stress and base not in _VOWELS:
        return None
    return _ARPABET_TABLE.get(base)


def _read_mfa_silence(label: str) -> str | None:
    return SILENCE if label.lower() in _MFA_SILENCES else None


def _read_mfa(label: str) -> str | None:
    return _read_mfa_silence(label) or _read_arpabet(label) or _read_ipa(label)


def _read_timit(label: str) -> str | None:
    return _TIMIT_TABLE.get(label.lower())


def _read_mocha(label: str) -> str | None:
    return _MOCHA_TABLE.get(label.lower())


def _read_espeak(label: str) -> str | None:
    if label == SILENCE:
        return SILENCE
    return _ESPEAK_TABLE.get(label.strip(_ESPEAK_STRESS))


def _read_sampa(label: str) -> str | None:
    if label == SILENCE:
        return SILENCE
    return _SAMPA_TABLE.get(label) or _SAMPA_TABLE.get(label.replace(":", ""))


def _ipa_base(text: str) -> str:
    """Drops length marks, secondary articulations and combining diacritics."""
    return "".join(c for c in text if c not in _IPA_MODIFIERS and not unicodedata.combining(c))


def _read_ipa_table(label: str) -> str | None:
    """The English IPA table's judgement for ``label``, if it has one."""
    if label == SILENCE:
        return SILENCE
    text = "".join(c for c in _nfd(label) if c not in _IPA_IGNORED)
    if not text:
        return None
    return _IPA_LOOKUP.get(text) or _IPA_LOOKUP.get(_ipa_base(text))


def _read_ipa(label: str) -> str | None:
    table = _read_ipa_table(label)
    if table is not None:
        return table
    try:
        return nearest_phoneme(label)
    except UnreadableSymbol:
        return None


def ipa_phonemes(label: str, where: str | None = None) -> tuple[str, ...]:
    """The phonemes an IPA ``label`` of any language holds, in order: the English table's
    one, else one per segment by articulatory features (a diphthong one for two vowels);
    ``()`` for a label of marks alone (a bare length mark). Raises ``UnknownPhonemeError``
    naming the symbol no table knows."""
    table = _read_ipa_table(label)
    if table is not None:
        return (table,)
    try:
        return phonemes_by_features(label)
    except UnreadableSymbol as exc:
        raise UnknownPhonemeError(str(exc), where=where) from None


# In "auto", ARPAbet is read first and case-insensitively, so espeak's
# capital consonants (D, T, S, Z, N, V) and "aa" need source="espeak".
_AUTO_ORDER: tuple[Callable[[str], str | None], ...] = (
    _read_arpabet,
    _read_mfa_silence,
    _read_timit,
    _read_espeak,
    _read_ipa,
)


def _read_auto(label: str) -> str | None:
    for reader in _AUTO_ORDER:
        canonical = reader(label)
        if canonical is not None:
            return canonical
    return None


_READERS: Mapping[str, Callable[[str], str | None]] = MappingProxyType(
    {
        "auto": _read_auto,
        "arpabet": _read_arpabet,
        "mfa": _read_mfa,
        "timit": _read_timit,
        "mocha": _read_mocha,
        "espeak": _read_espeak,
        "ipa": _read_ipa,
        "sampa": _read_sampa,
    }
)


@lru_cache(maxsize=8192)
def _lookup(label: str, source: str) -> str | None:
    return _READERS[source](label.strip())


def _reader_name(source: str, where: str | None) -> str:
    name = SOURCE_ALIASES.get(source, source)
    if name not in _READERS:
        raise LipstreamError(
            f"unknown phoneme source {source!r}; expected one of "
            f"{', '.join(SOURCES + tuple(SOURCE_ALIASES))}",
            where=where,
            code="unknown_phoneme_source",
        )
    return name


def normalize_phoneme(label: str, source: str = "auto", where: str | None = None) -> str:
    """The canonical label (one of ``PHONEMES``) for ``label`` written in ``source``.

    ``source`` is one of ``SOURCES`` (or an alias in ``SOURCE_ALIASES``);
    ``where`` locates the label in error messages, e.g. ``"utt01.TextGrid:line 42"``.
    Raises ``UnknownPhonemeError`` for a label the source does not define.
    """
    name = _reader_name(source, where)
    if not isinstance(label, str):
        raise UnknownPhonemeError(
            f"phoneme label must be a string, got {type(label).__name__} {label!r}",
            where=where,
        )
    canonical = _lookup(label, name)
    if canonical is None:
        raise UnknownPhonemeError(f"unknown phoneme {label!r} for source {source!r}", where=where)
    return canonical


@cache
def kept_labels(source: str = "auto") -> frozenset[str]:
    """The canonical labels that ``source`` reads as themselves: for these, and only these,
    ``normalize_phoneme(label, source) == label`` (any other label normalizes to a
    canonical one, so differs from it). A set lookup for callers that re-check labels."""
    name = _reader_name(source, None)
    return frozenset(label for label in PHONEMES if _lookup(label, name) == label)


def normalize_phonemes(
    labels: Iterable[str], source: str = "auto", where: str | None = None
) -> list[str]:
    """Canonical labels for a sequence; errors locate the item as ``where[i]``."""
    prefix = where or ""
    return [
        normalize_phoneme(label, source, f"{prefix}[{index}]") for index, label in enumerate(labels)
    ]


# Narrowest notation first, so plain ARPAbet is not read as espeak; SAMPA
# after espeak, whose mnemonics it shares; "mfa" is ARPAbet or IPA plus
# silence tokens, so it comes after both.
_DETECTION_ORDER = ("arpabet", "timit", "mocha", "espeak", "ipa", "sampa", "mfa", "auto")


def detect_source(labels: Iterable[str], where: str | None = None) -> str:
    """The first source in ``_DETECTION_ORDER`` that reads every one of ``labels``.

    Meant for a whole file of labels: MOCHA-TIMIT's MRPA vowels ("uh" is /ʌ/)
    clash with TIMIT's ("uh" is /ʊ/), and only the file as a whole tells them
    apart. Raises ``UnknownPhonemeError`` naming a label no source reads, or
    saying that the labels mix notations.
    """
    items = list(labels)
    for label in items:
        if not isinstance(label, str):
            raise UnknownPhonemeError(f"phoneme label must be a string, got {label!r}", where=where)
    distinct = list(dict.fromkeys(items))
    for source in _DETECTION_ORDER:
        if all(_lookup(label, source) is not None for label in distinct):
            return source
    for label in distinct:
        if all(_lookup(label, source) is None for source in _READERS):
            raise UnknownPhonemeError(f"unknown phoneme {label!r} in every source", where=where)
    raise UnknownPhonemeError(
        f"labels mix notations: no one source reads all of {distinct[:8]!r}", where=where
    )


def is_silence(label: str, source: str = "auto", where: str | None = None) -> bool:
    """True when ``label`` normalizes to ``SILENCE``; unknown labels raise."""
    return normalize_phoneme(label, source, where) == SILENCE
