"""Channel names of output profiles: naming styles and the viseme sets.

Sketch: models name channels in ARKit style (``jawOpen``, ``eyeBlinkLeft``).
The ``livelink`` style (Live Link Face, Audio2Face) capitalises the first
letter (``JawOpen``); ``suffix_lr`` turns a trailing ``Left``/``Right`` into
``_L``/``_R`` (``eyeBlink_L``). The Oculus (OVRLipSync) viseme set has a fixed
order of 15 names; rigs spell them ``viseme_I`` or, as OVRLipSync's enum
does, ``ih``, and both spellings are accepted. The Preston Blair set is
Rhubarb Lip Sync's nine mouth shapes ``A``-``H`` and ``X``, in any case.
"""

from __future__ import annotations

from .messages import Naming, VisemeSet

_OCULUS15_VISEMES_TEXT = """
    viseme_sil viseme_PP viseme_FF viseme_TH viseme_DD
    viseme_kk viseme_CH viseme_SS viseme_nn viseme_RR
    viseme_aa viseme_E viseme_I viseme_O viseme_U
"""
OCULUS15_VISEMES: tuple[str, ...] = tuple(_OCULUS15_VISEMES_TEXT.split())
PRESTON_BLAIR_SHAPES: tuple[str, ...] = ("A", "B", "C", "D", "E", "F", "G", "H", "X")
VISEME_CHANNELS: dict[VisemeSet, tuple[str, ...]] = {
    "oculus15": OCULUS15_VISEMES,
    "preston-blair": PRESTON_BLAIR_SHAPES,
}
RETARGET_PRESETS: tuple[str, ...] = tuple(
    "oculus15 arkit52 vrm1 vrm0 vroid rpm unified metahuman a2f68".split()
)
"""The rig presets every server offers by name in ``output.retarget`` (``arkit52``,
``unified``, ``metahuman`` and ``a2f68`` only for a model with ARKit channel names);
docs/how-to/retarget.md lists each one's controls and key poses."""
_VISEME_PREFIX = "viseme_"
_OVR_SPELLINGS = {"ih": "viseme_I", "oh": "viseme_O", "ou": "viseme_U"}
_SIDE_SUFFIXES = (("Left", "_L"), ("Right", "_R"))


def rename_channel(arkit_name: str, naming: Naming) -> str:
    """An ARKit channel name in the given naming style."""
    if naming == "livelink":
        return arkit_name[:1].upper() + arkit_name[1:]
    if naming == "suffix_lr":
        for side, suffix in _SIDE_SUFFIXES:
            if arkit_name.endswith(side) and len(arkit_name) > len(side):
                return arkit_name[: -len(side)] + suffix
    return arkit_name


def canonical_viseme(name: str, viseme_set: VisemeSet = "oculus15") -> str | None:
    """The channel of ``viseme_set`` that ``name`` denotes, None if none: for ``oculus15``,
    ``viseme_I``, ``I``, ``ih`` and ``viseme_ih`` -> ``viseme_I``; for ``preston-blair``,
    ``a`` -> ``A``."""
    if viseme_set == "preston-blair":
        shape = name.strip().upper()
        return shape if shape in PRESTON_BLAIR_SHAPES else None
    bare = name.removeprefix(_VISEME_PREFIX)
    if bare in _OVR_SPELLINGS:
        return _OVR_SPELLINGS[bare]
    candidate = _VISEME_PREFIX + bare
    return candidate if candidate in OCULUS15_VISEMES else None
