"""Viseme schemes: how the 40 canonical phonemes group into mouth shapes.

Method: a scheme is a total map from ``phonemes.PHONEMES`` to an ordered
tuple of viseme classes; any label ``normalize_phoneme`` accepts is first
made canonical and then looked up. Three schemes ship:

* ``deng15``: the 15 categories of Deng & Neumann (2008), Appendix A, Table VI.
* ``oculus15``: the 15 Oculus/Meta OVR LipSync visemes, in the SDK's index order.
* ``preston-blair``: the Preston Blair mouth shapes A-H and X used by Rhubarb Lip Sync.

``docs/reference/phonemes.md`` lists every mapping and the reasons for the choices the
sources leave open.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

from .errors import LipstreamError
from .phonemes import PHONEMES, normalize_phoneme
from .tables import names


@dataclass(frozen=True, eq=False)
class VisemeScheme:
    """A named grouping of canonical phonemes into ordered viseme classes.

    ``mapping`` takes each of the 40 canonical labels to a member of
    ``classes``; ``aliases`` takes other spellings of a class name (matched
    case-insensitively) to the class.
    """

    name: str
    classes: tuple[str, ...]
    mapping: Mapping[str, str]
    aliases: Mapping[str, str] = field(default_factory=lambda: MappingProxyType({}))
    _by_folded_name: Mapping[str, str] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        missing = [p for p in PHONEMES if p not in self.mapping]
        strays = sorted(set(self.mapping.values()) - set(self.classes))
        if missing or strays or len(set(self.classes)) != len(self.classes):
            raise ValueError(
                f"viseme scheme {self.name!r} is malformed: unmapped {missing}, "
                f"unknown classes {strays}"
            )
        object.__setattr__(self, "mapping", MappingProxyType(dict(self.mapping)))
        folded = {c.lower(): c for c in self.classes}
        folded |= {alias.lower(): target for alias, target in self.aliases.items()}
        object.__setattr__(self, "_by_folded_name", MappingProxyType(folded))

    def viseme_of(self, phoneme: str, source: str = "auto", where: str | None = None) -> str:
        """The class of ``phoneme``, a label in ``source`` notation (see ``normalize_phoneme``)."""
        viseme = self.mapping.get(phoneme) if source == "auto" else None
        if viseme is not None:
            return viseme
        return self.mapping[normalize_phoneme(phoneme, source, where)]

    def index_of(self, phoneme: str, source: str = "auto", where: str | None = None) -> int:
        """Position of ``phoneme``'s class in ``classes``."""
        return self.classes.index(self.viseme_of(phoneme, source, where))

    def members(self, viseme: str) -> tuple[str, ...]:
        """Canonical phonemes of class ``viseme`` (any accepted spelling), in ``PHONEMES`` order."""
        name = self.class_name(viseme)
        return tuple(p for p in PHONEMES if self.mapping[p] == name)

    def class_name(self, name: str, where: str | None = None) -> str:
        """The class that ``name`` (the class itself or an alias, any case) denotes."""
        found = self._by_folded_name.get(name.strip().lower()) if isinstance(name, str) else None
        if found is None:
            raise LipstreamError(
                f"unknown viseme {name!r} in scheme {self.name!r}; expected one of "
                f"{', '.join(self.classes)}",
                where=where,
                code="unknown_viseme",
            )
        return found


def _scheme(
    name: str, groups: Mapping[str, str], aliases: Mapping[str, str] | None = None
) -> VisemeScheme:
    """Builds a scheme from ``class -> space-separated phonemes``, keeping class order."""
    mapping = {p: viseme for viseme, members in groups.items() for p in members.split()}
    return VisemeScheme(name, tuple(groups), mapping, MappingProxyType(dict(aliases or {})))


# Table VI in reading order. The paper's /ax/ is our AH, its "/yl/" (an
# extraction of /y/) is Y; /el/ /em/ /en/ have no canonical label of their own.
DENG15 = _scheme(
    "deng15",
    {
        "pau": "sil",
        "r": "R",
        "k-g-ng": "K G NG",
        "ae-ax-ah-aa": "AE AH AA",
        "f-v": "F V",
        "ch-sh-jh": "CH SH JH",
        "ao-y-iy-ih-ay-aw": "AO Y IY IH AY AW",
        "ow-oy": "OW OY",
        "n-d-t-l": "N D T L",
        "ey-eh-el-em-en-er": "EY EH ER",
        "th-dh": "TH DH",
        "s-z-zh": "S Z ZH",
        "b-p-m": "B P M",
        "hh": "HH",
        "w-uw-uh": "W UW UH",
    },
)

# OVRLipSync's Viseme enum order; blend shapes are named "viseme_<name>".
OCULUS_VISEMES: tuple[str, ...] = names("sil PP FF TH DD kk CH SS nn RR aa E I O U")
OCULUS15 = _scheme(
    "oculus15",
    {
        "sil": "sil",
        "PP": "P B M",
        "FF": "F V",
        "TH": "TH DH",
        "DD": "T D",
        "kk": "K G NG HH",
        "CH": "CH JH SH ZH",
        "SS": "S Z",
        "nn": "N L",
        "RR": "R ER",
        "aa": "AA AE AH AY AW",
        "E": "EH EY",
        "I": "IH IY Y",
        "O": "AO OW OY",
        "U": "UH UW W",
    },
    {"ih": "I", "oh": "O", "ou": "U"} | {f"viseme_{name}": name for name in OCULUS_VISEMES},
)

PRESTON_BLAIR = _scheme(
    "preston-blair",
    {
        "A": "P B M",
        "B": "IY IH Y K G NG T D N S Z SH ZH CH JH TH DH HH R",
        "C": "EH EY AE AH",
        "D": "AA AY AW",
        "E": "AO ER OY",
        "F": "UW UH OW W",
        "G": "F V",
        "H": "L",
        "X": "sil",
    },
)

SCHEMES: Mapping[str, VisemeScheme] = MappingProxyType(
    {scheme.name: scheme for scheme in (DENG15, OCULUS15, PRESTON_BLAIR)}
)
SCHEME_ALIASES: Mapping[str, str] = MappingProxyType(
    {"deng": "deng15", "oculus": "oculus15", "ovr": "oculus15", "rhubarb": "preston-blair"}
)


def get_scheme(name: str, where: str | None = None) -> VisemeScheme:
    """The scheme called ``name`` (or an alias in ``SCHEME_ALIASES``), case-insensitive."""
    key = name.strip().lower() if isinstance(name, str) else ""
    scheme = SCHEMES.get(SCHEME_ALIASES.get(key, key))
    if scheme is None:
        raise LipstreamError(
            f"unknown viseme scheme {name!r}; expected one of {', '.join(SCHEMES)}",
            where=where,
            code="unknown_viseme_scheme",
        )
    return scheme


def oculus_viseme_name(name: str, where: str | None = None) -> str:
    """Short OVR name for ``name``: ``"viseme_I"``, ``"ih"`` and ``"I"`` all give ``"I"``."""
    return OCULUS15.class_name(name, where)
