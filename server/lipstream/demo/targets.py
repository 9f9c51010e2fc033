"""Articulatory targets of each phoneme for the demo character's face generator.

Sketch: five articulators (tract variables in the task-dynamics sense) carry
speech on the lower face: jaw opening, lip aperture, lip rounding/protrusion,
lip spreading and lower-lip tuck (lower lip under the upper teeth). Each
phoneme gives every articulator a *window* [lo, hi] of acceptable values
(Keating's window model): a narrow window is a hard requirement (bilabial
closure, labiodental tuck, rounded vowels), a wide one leaves the articulator
free to coarticulate with its neighbours. Diphthongs are two targets in a row.

The lip windows of L, S/Z, IY, EY, R and TH/DH are calibrated to the real-face set's
mean aperture per phoneme (docs/explanation/demo-character.md, "Calibration to real
faces").

Units are the output's: jaw and lip aperture in jawOpen units (0 closed, 1
fully open); a negative lip aperture is a *virtual target* past contact, which
the lips press towards while held together. Rounding, spread and tuck are 0..1.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

from ..errors import UnknownPhonemeError


class Articulator(IntEnum):
    """Columns of the articulator state, in this order."""

    JAW = 0
    LIPS = 1
    ROUND = 2
    SPREAD = 3
    TUCK = 4


N_ARTICULATORS = len(Articulator)
NARROW_WIDTH = 0.08
"""A window at most this wide is a requirement, not a tolerance."""

Window = tuple[float, float]
WindowLike = float | Window

FREE: Window = (0.0, 1.0)


@dataclass(frozen=True)
class GestureTarget:
    """One articulatory target: a window per articulator (indexed by ``Articulator``).

    ``contact`` marks targets whose lips touch something (lips together, or the
    lower lip on the upper teeth): the lips hold them for most of the phoneme.
    """

    windows: tuple[Window, Window, Window, Window, Window]
    contact: bool = False

    def window(self, articulator: Articulator) -> Window:
        return self.windows[articulator]

    def is_narrow(self, articulator: Articulator) -> bool:
        low, high = self.windows[articulator]
        return high - low <= NARROW_WIDTH


def _window(value: WindowLike) -> Window:
    if isinstance(value, tuple):
        return (float(value[0]), float(value[1]))
    return (float(value), float(value))


def _target(
    jaw: WindowLike,
    lips: WindowLike,
    rounding: WindowLike,
    spread: WindowLike,
    tuck: WindowLike = 0.0,
    contact: bool = False,
) -> GestureTarget:
    return GestureTarget(
        (_window(jaw), _window(lips), _window(rounding), _window(spread), _window(tuck)), contact
    )


_OPEN_A = _target(0.52, 0.45, (0.0, 0.15), (0.0, 0.15))
_HIGH_FRONT = _target(0.17, 0.15, 0.0, 0.42)
_ROUND_HIGH = _target(0.19, 0.12, 0.65, 0.0)
_POSTALVEOLAR = _target(0.07, (0.06, 0.16), (0.35, 0.7), (0.0, 0.1))
_ALVEOLAR = _target((0.04, 0.14), (0.04, 0.35), FREE, FREE)
_VELAR = _target((0.05, 0.35), (0.04, 0.45), FREE, FREE)
_DENTAL = _target(0.1, (0.0, 0.09), FREE, FREE)
_SIBILANT = _target(0.12, (0.10, 0.27), FREE, FREE)

PHONEME_TARGETS: dict[str, tuple[GestureTarget, ...]] = {
    "sil": (_target(0.02, 0.0, FREE, FREE),),
    "IY": (_target(0.17, 0.17, 0.0, 0.55),),
    "IH": (_target(0.18, 0.16, 0.0, 0.35),),
    "EH": (_target(0.30, 0.26, 0.0, 0.30),),
    "AE": (_target(0.48, 0.42, 0.0, 0.35),),
    "AA": (_target(0.55, 0.48, (0.0, 0.15), (0.0, 0.15)),),
    "AH": (_target((0.22, 0.36), (0.18, 0.32), (0.0, 0.3), (0.0, 0.2)),),
    "AO": (_target(0.42, 0.30, 0.55, 0.0),),
    "ER": (_target(0.20, 0.14, 0.40, 0.0),),
    "UH": (_target(0.20, 0.14, 0.55, 0.0),),
    "UW": (_target(0.12, 0.08, 0.90, 0.0),),
    "AY": (_OPEN_A, _HIGH_FRONT),
    "AW": (_OPEN_A, _ROUND_HIGH),
    "EY": (_target(0.33, 0.29, 0.0, 0.35), _target(0.20, 0.19, 0.0, 0.5)),
    "OW": (_target(0.34, 0.24, 0.55, 0.0), _target(0.18, 0.12, 0.80, 0.0)),
    "OY": (_target(0.40, 0.28, 0.55, 0.0), _HIGH_FRONT),
    "P": (_target(0.08, -0.12, FREE, FREE, contact=True),),
    "B": (_target(0.08, -0.10, FREE, FREE, contact=True),),
    "M": (_target(0.07, -0.07, FREE, FREE, contact=True),),
    "F": (_target(0.07, 0.03, FREE, FREE, tuck=1.0, contact=True),),
    "V": (_target(0.07, 0.04, FREE, FREE, tuck=0.9, contact=True),),
    "TH": (_DENTAL,),
    "DH": (_DENTAL,),
    "T": (_ALVEOLAR,),
    "D": (_ALVEOLAR,),
    "N": (_ALVEOLAR,),
    "L": (_target((0.19, 0.34), (0.19, 0.54), FREE, FREE),),
    "S": (_SIBILANT,),
    "Z": (_SIBILANT,),
    "SH": (_POSTALVEOLAR,),
    "ZH": (_POSTALVEOLAR,),
    "CH": (_POSTALVEOLAR,),
    "JH": (_POSTALVEOLAR,),
    "K": (_VELAR,),
    "G": (_VELAR,),
    "NG": (_target((0.05, 0.3), (0.04, 0.4), FREE, FREE),),
    "HH": (_target((0.0, 0.7), (0.02, 0.6), FREE, FREE),),
    "R": (_target((0.08, 0.2), (0.04, 0.1), (0.35, 0.55), 0.0),),
    "W": (_target(0.09, 0.05, 0.90, 0.0),),
    "Y": (_target(0.1, (0.08, 0.18), (0.0, 0.1), (0.3, 0.5)),),
}

VOWELS: frozenset[str] = frozenset(
    {"IY", "IH", "EH", "AE", "AA", "AH", "AO", "ER", "UH", "UW", "AY", "AW", "EY", "OW", "OY"}
)
DIPHTHONG_SPLIT = 0.55
"""Fraction of a diphthong's span given to its first target."""


def gesture_targets(phoneme: str, where: str = "phoneme") -> tuple[GestureTarget, ...]:
    """The one or two targets of a canonical ARPAbet label (or ``sil``)."""
    try:
        return PHONEME_TARGETS[phoneme]
    except KeyError:
        raise UnknownPhonemeError(
            f"the demo face has no articulatory target for {phoneme!r}", where=where
        ) from None
