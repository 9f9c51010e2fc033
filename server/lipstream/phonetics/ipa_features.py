"""IPA symbols described by their articulation: the feature table.

Method: every base symbol of the IPA chart (and the few non-chart letters
espeak-ng writes) is a ``Consonant`` (place, manner, voicing, nasality,
laterality, rhoticity, lip rounding) or a ``Vowel`` (height, backness, lip
rounding, nasality, rhoticity). Features are numbers on scales where a
distance means something: place runs from the lips (0) back to the glottis,
with the places behind the teeth close together because the face does not
show them apart; manner is a degree of stricture (stop 0 ... approximant 3);
vowel height runs from open (0) to close (1) in the chart's seven steps and
backness from front (0) to back (1). Diacritics and modifier letters change a
segment's features (``DIACRITICS``: nasalized, devoiced, lowered, centralized,
labialized, rhotic, dental, ...); the marks that change no feature lipstream
can show (length, stress, aspiration, secondary palatalization, ...) are
``IGNORED_MARKS``. Values follow the IPA chart (2020) and the Handbook of the
IPA's definitions.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from types import MappingProxyType

BILABIAL = 0.0
LABIODENTAL = 1.0
DENTAL = 2.0
ALVEOLAR = 3.0
POSTALVEOLAR = 3.5
RETROFLEX = 3.7
ALVEOLO_PALATAL = 3.8
PALATAL = 4.2
VELAR = 4.8
UVULAR = 5.1
PHARYNGEAL = 5.4
GLOTTAL = 5.6

STOP = 0.0
TAP = 0.5
AFFRICATE = 1.4
FRICATIVE = 2.0
TRILL = 2.2
APPROXIMANT = 3.0

CLOSE, NEAR_CLOSE, CLOSE_MID, MID, OPEN_MID, NEAR_OPEN, OPEN = (
    1.0,
    5 / 6,
    4 / 6,
    0.5,
    2 / 6,
    1 / 6,
    0.0,
)
FRONT, NEAR_FRONT, CENTRAL, NEAR_BACK, BACK = (0.0, 0.25, 0.5, 0.75, 1.0)


@dataclass(frozen=True)
class Consonant:
    """``place`` and ``stricture`` on the scales above; ``rounded`` in [0, 1] (lip rounding)."""

    place: float
    stricture: float
    voiced: bool
    nasal: bool = False
    lateral: bool = False
    rhotic: bool = False
    rounded: float = 0.0


@dataclass(frozen=True)
class Vowel:
    """``height`` (open 0 .. close 1), ``backness`` (front 0 .. back 1), ``rounded`` in [0, 1]."""

    height: float
    backness: float
    rounded: float
    nasal: bool = False
    rhotic: bool = False


Segment = Consonant | Vowel


def _c(place: float, stricture: float, voiced: bool, **more: bool | float) -> Consonant:
    return Consonant(place, stricture, voiced, **more)  # type: ignore[arg-type]


def _v(height: float, backness: float, rounded: float, **more: bool) -> Vowel:
    return Vowel(height, backness, rounded, **more)


_NASAL = {"nasal": True}
_LATERAL = {"lateral": True}
_RHOTIC = {"rhotic": True}

CONSONANTS: Mapping[str, Consonant] = MappingProxyType(
    {
        # stops
        "p": _c(BILABIAL, STOP, False),
        "b": _c(BILABIAL, STOP, True),
        "t": _c(ALVEOLAR, STOP, False),
        "d": _c(ALVEOLAR, STOP, True),
        "ʈ": _c(RETROFLEX, STOP, False),
        "ɖ": _c(RETROFLEX, STOP, True),
        "c": _c(PALATAL, STOP, False),
        "ɟ": _c(PALATAL, STOP, True),
        "k": _c(VELAR, STOP, False),
        "ɡ": _c(VELAR, STOP, True),
        "g": _c(VELAR, STOP, True),
        "q": _c(UVULAR, STOP, False),
        "ɢ": _c(UVULAR, STOP, True),
        "ʡ": _c(PHARYNGEAL, STOP, False),
        "ʔ": _c(GLOTTAL, STOP, False),
        # implosives and clicks: stops at their place
        "ɓ": _c(BILABIAL, STOP, True),
        "ɗ": _c(ALVEOLAR, STOP, True),
        "ᶑ": _c(RETROFLEX, STOP, True),
        "ʄ": _c(PALATAL, STOP, True),
        "ɠ": _c(VELAR, STOP, True),
        "ʛ": _c(UVULAR, STOP, True),
        "ʘ": _c(BILABIAL, STOP, False),
        "ǀ": _c(DENTAL, STOP, False),
        "ǃ": _c(POSTALVEOLAR, STOP, False),
        "ǂ": _c(PALATAL, STOP, False),
        "ǁ": _c(ALVEOLAR, STOP, False, lateral=True),
        # nasals
        "m": _c(BILABIAL, STOP, True, **_NASAL),
        "ɱ": _c(LABIODENTAL, STOP, True, **_NASAL),
        "n": _c(ALVEOLAR, STOP, True, **_NASAL),
        "ɳ": _c(RETROFLEX, STOP, True, **_NASAL),
        "ɲ": _c(PALATAL, STOP, True, **_NASAL),
        "ŋ": _c(VELAR, STOP, True, **_NASAL),
        "ɴ": _c(UVULAR, STOP, True, **_NASAL),
        # trills, taps and flaps
        "ʙ": _c(BILABIAL, TRILL, True),
        "r": _c(ALVEOLAR, TRILL, True, **_RHOTIC),
        "ʀ": _c(UVULAR, TRILL, True, **_RHOTIC),
        "ⱱ": _c(LABIODENTAL, TAP, True),
        "ɾ": _c(ALVEOLAR, TAP, True, **_RHOTIC),
        "ɽ": _c(RETROFLEX, TAP, True, **_RHOTIC),
        "ɺ": _c(ALVEOLAR, TAP, True, lateral=True),
        # fricatives
        "ɸ": _c(BILABIAL, FRICATIVE, False),
        "β": _c(BILABIAL, FRICATIVE, True),
        "f": _c(LABIODENTAL, FRICATIVE, False),
        "v": _c(LABIODENTAL, FRICATIVE, True),
        "θ": _c(DENTAL, FRICATIVE, False),
        "ð": _c(DENTAL, FRICATIVE, True),
        "s": _c(ALVEOLAR, FRICATIVE, False),
        "z": _c(ALVEOLAR, FRICATIVE, True),
        "ʃ": _c(POSTALVEOLAR, FRICATIVE, False),
        "ʒ": _c(POSTALVEOLAR, FRICATIVE, True),
        "ʂ": _c(RETROFLEX, FRICATIVE, False),
        "ʐ": _c(RETROFLEX, FRICATIVE, True),
        "ɕ": _c(ALVEOLO_PALATAL, FRICATIVE, False),
        "ʑ": _c(ALVEOLO_PALATAL, FRICATIVE, True),
        "ç": _c(PALATAL, FRICATIVE, False),
        "ʝ": _c(PALATAL, FRICATIVE, True),
        "x": _c(VELAR, FRICATIVE, False),
        "ɣ": _c(VELAR, FRICATIVE, True),
        "χ": _c(UVULAR, FRICATIVE, False),
        "ʁ": _c(UVULAR, FRICATIVE, True, **_RHOTIC),
        "ħ": _c(PHARYNGEAL, FRICATIVE, False),
        "ʕ": _c(PHARYNGEAL, FRICATIVE, True),
        "ʜ": _c(PHARYNGEAL, FRICATIVE, False),
        "ʢ": _c(PHARYNGEAL, FRICATIVE, True),
        "h": _c(GLOTTAL, FRICATIVE, False),
        "ɦ": _c(GLOTTAL, FRICATIVE, True),
        "ɧ": _c(POSTALVEOLAR, FRICATIVE, False, rounded=0.5),
        "ɬ": _c(ALVEOLAR, FRICATIVE, False, **_LATERAL),
        "ɮ": _c(ALVEOLAR, FRICATIVE, True, **_LATERAL),
        # approximants
        "ʋ": _c(LABIODENTAL, APPROXIMANT, True),
        "ɹ": _c(POSTALVEOLAR, APPROXIMANT, True, **_RHOTIC),
        "ɻ": _c(RETROFLEX, APPROXIMANT, True, **_RHOTIC),
        "j": _c(PALATAL, APPROXIMANT, True),
        "ɰ": _c(VELAR, APPROXIMANT, True),
        "w": _c(VELAR, APPROXIMANT, True, rounded=1.0),
        "ʍ": _c(VELAR, APPROXIMANT, False, rounded=1.0),
        "ɥ": _c(PALATAL, APPROXIMANT, True, rounded=1.0),
        "l": _c(ALVEOLAR, APPROXIMANT, True, **_LATERAL),
        "ɫ": _c(ALVEOLAR, APPROXIMANT, True, **_LATERAL),
        "ɭ": _c(RETROFLEX, APPROXIMANT, True, **_LATERAL),
        "ʎ": _c(PALATAL, APPROXIMANT, True, **_LATERAL),
        "ʟ": _c(VELAR, APPROXIMANT, True, **_LATERAL),
        # precomposed affricates
        "ʦ": _c(ALVEOLAR, AFFRICATE, False),
        "ʣ": _c(ALVEOLAR, AFFRICATE, True),
        "ʧ": _c(POSTALVEOLAR, AFFRICATE, False),
        "ʤ": _c(POSTALVEOLAR, AFFRICATE, True),
        "ʨ": _c(ALVEOLO_PALATAL, AFFRICATE, False),
        "ʥ": _c(ALVEOLO_PALATAL, AFFRICATE, True),
    }
)

VOWELS: Mapping[str, Vowel] = MappingProxyType(
    {
        "i": _v(CLOSE, FRONT, 0),
        "y": _v(CLOSE, FRONT, 1),
        "ɨ": _v(CLOSE, CENTRAL, 0),
        "ʉ": _v(CLOSE, CENTRAL, 1),
        "ɯ": _v(CLOSE, BACK, 0),
        "u": _v(CLOSE, BACK, 1),
        "ɪ": _v(NEAR_CLOSE, NEAR_FRONT, 0),
        "ʏ": _v(NEAR_CLOSE, NEAR_FRONT, 1),
        "ᵻ": _v(NEAR_CLOSE, CENTRAL, 0),
        "ᵿ": _v(NEAR_CLOSE, CENTRAL, 1),
        "ʊ": _v(NEAR_CLOSE, NEAR_BACK, 1),
        "ɩ": _v(NEAR_CLOSE, NEAR_FRONT, 0),
        "ɷ": _v(NEAR_CLOSE, NEAR_BACK, 1),
        "e": _v(CLOSE_MID, FRONT, 0),
        "ø": _v(CLOSE_MID, FRONT, 1),
        "ɘ": _v(CLOSE_MID, CENTRAL, 0),
        "ɵ": _v(CLOSE_MID, CENTRAL, 1),
        "ɤ": _v(CLOSE_MID, BACK, 0),
        "o": _v(CLOSE_MID, BACK, 1),
        "ə": _v(MID, CENTRAL, 0),
        "ɚ": _v(MID, CENTRAL, 0, **_RHOTIC),
        "ɛ": _v(OPEN_MID, FRONT, 0),
        "œ": _v(OPEN_MID, FRONT, 1),
        "ɜ": _v(OPEN_MID, CENTRAL, 0),
        "ɞ": _v(OPEN_MID, CENTRAL, 1),
        "ʌ": _v(OPEN_MID, BACK, 0),
        "ɔ": _v(OPEN_MID, BACK, 1),
        "ɝ": _v(OPEN_MID, CENTRAL, 0, **_RHOTIC),
        "æ": _v(NEAR_OPEN, FRONT, 0),
        "ɐ": _v(NEAR_OPEN, CENTRAL, 0),
        "a": _v(OPEN, FRONT, 0),
        "ɶ": _v(OPEN, FRONT, 1),
        "ɑ": _v(OPEN, BACK, 0),
        "ɒ": _v(OPEN, BACK, 1),
    }
)

BASE_SYMBOLS: Mapping[str, Segment] = MappingProxyType({**CONSONANTS, **VOWELS})


def _toward(value: float, target: float, share: float) -> float:
    return value + (target - value) * share


def _clip(value: float) -> float:
    return min(1.0, max(0.0, value))


def _nasalized(segment: Segment) -> Segment:
    return replace(segment, nasal=True)


def _voiceless(segment: Segment) -> Segment:
    return replace(segment, voiced=False) if isinstance(segment, Consonant) else segment


def _voiced(segment: Segment) -> Segment:
    return replace(segment, voiced=True) if isinstance(segment, Consonant) else segment


def _rounding(amount: float) -> Callable[[Segment], Segment]:
    def change(segment: Segment) -> Segment:
        return replace(segment, rounded=_clip(segment.rounded + amount))

    return change


def _labialized(segment: Segment) -> Segment:
    return replace(segment, rounded=1.0)


def _compressed(segment: Segment) -> Segment:
    return replace(segment, rounded=max(segment.rounded, 0.5))


def _lowered(segment: Segment) -> Segment:
    if isinstance(segment, Vowel):
        return replace(segment, height=_clip(segment.height - 1 / 6))
    return replace(segment, stricture=min(APPROXIMANT, segment.stricture + 1.0))


def _raised(segment: Segment) -> Segment:
    if isinstance(segment, Vowel):
        return replace(segment, height=_clip(segment.height + 1 / 6))
    return replace(segment, stricture=max(STOP, segment.stricture - 1.0))


def _centralized(segment: Segment) -> Segment:
    return replace(segment, backness=CENTRAL) if isinstance(segment, Vowel) else segment


def _mid_centralized(segment: Segment) -> Segment:
    if isinstance(segment, Consonant):
        return segment
    return replace(
        segment,
        backness=_toward(segment.backness, CENTRAL, 0.5),
        height=_toward(segment.height, MID, 0.5),
    )


def _advanced(segment: Segment) -> Segment:
    if isinstance(segment, Vowel):
        return replace(segment, backness=_clip(segment.backness - 0.25))
    return replace(segment, place=max(BILABIAL, segment.place - 0.3))


def _retracted(segment: Segment) -> Segment:
    if isinstance(segment, Vowel):
        return replace(segment, backness=_clip(segment.backness + 0.25))
    return replace(segment, place=min(GLOTTAL, segment.place + 0.3))


def _dental(segment: Segment) -> Segment:
    return replace(segment, place=DENTAL) if isinstance(segment, Consonant) else segment


def _rhotic(segment: Segment) -> Segment:
    return replace(segment, rhotic=True)


DIACRITICS: Mapping[str, Callable[[Segment], Segment]] = MappingProxyType(
    {
        "\u0303": _nasalized,  # combining tilde
        "\u0325": _voiceless,  # ring below
        "\u030a": _voiceless,  # ring above
        "\u032c": _voiced,  # caron below
        "ʷ": _labialized,
        "ᵝ": _compressed,
        "\u0339": _rounding(0.25),  # more rounded
        "\u031c": _rounding(-0.25),  # less rounded
        "\u031e": _lowered,
        "\u031d": _raised,
        "˕": _lowered,
        "˔": _raised,
        "\u0308": _centralized,
        "\u033d": _mid_centralized,
        "\u031f": _advanced,
        "\u0320": _retracted,
        "˖": _advanced,
        "˗": _retracted,
        "\u032a": _dental,
        "\u0346": _dental,
        "˞": _rhotic,
    }
)

IGNORED_MARKS = frozenset(
    "ˈˌ.‿"  # stress, syllable break, linking
    "ːˑ:"  # length (also ASCII ":")
    "ʰʱʲˠˤⁿˡʼ"  # aspiration, secondary articulations, releases, ejective
    "\u0329\u030d\u032f\u0311"  # syllabic, non-syllabic
    "\u033a\u033b\u033c"  # apical, laminal, linguolabial
    "\u0318\u0319\u0330\u0324\u031a\u0334"  # tongue root, creaky, breathy, no release, velarized
    "ᵊᶿˀ"
)
TIES = frozenset("\u0361\u035c")

# A modifier letter standing alone (espeak-ng writes palatalization as its own
# phoneme) is the segment it is a small copy of.
MODIFIER_LETTERS: Mapping[str, str] = MappingProxyType(
    {"ʲ": "j", "ʷ": "w", "ʰ": "h", "ʱ": "ɦ", "ˠ": "ɣ", "ˤ": "ʕ", "ⁿ": "n", "ˡ": "l", "ᵊ": "ə"}
)
