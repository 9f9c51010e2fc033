"""Rig presets for vowel-only rigs: VRM 1.0 (vrm1), VRM 0.x (vrm0) and VRoid (vroid).

Sketch: these rigs show speech with five vowel shapes only (あいうえお: A I
U E O) plus a blink and whole-face emotions. A projection onto five vowels
would leave the mouth in some vowel on every consonant ("always in A
shape"), so the map holds a key pose for every Oculus viseme class, each
with vowel controls chosen for it (``VOWEL_KEYS``): the closed-lip consonants
/p b m/ are a key whose controls are all 0, so the mouth closes; rounded
sounds (/uw uh w/) are ``U`` (``ou``); the other consonants are small
openings. A key pose is the model's probed pose of its viseme class (the mean
of its phonemes' poses, as ``oculus15`` probes them) on the mouth channels
only; rest is silence, every control 0 but the rig's neutral face. An engine
that coarticulates closes its lips in the shape of the vowels around them
(rounded in /uw b uw/), which the vowel keys would read as a vowel; so each
bilabial probed in context (``probes.CLOSURE_CONTEXTS``: after a silence or
a vowel, before a vowel) is one more closed-mouth key, every vowel 0.

Off the mouth: a blink key (``eyeBlinkLeft`` and ``eyeBlinkRight`` at 1, for
a model that has them) drives the rig's blink, and each emotion the model
shows (its rest pose in that emotion minus the neutral one, off the mouth
channels) drives the rig's emotion (``happy``→``happy``/``Joy``/``Fcl_ALL_Joy``,
``angry``, ``sad``→``sad``/``Sorrow``); the rig's neutral face is 1 at rest
and falls as an emotion rises. What speech does off the mouth (a brow the
model raises on /uw/) is a key of its own, each viseme class's pose there
with the neutral face, so speaking is not read as an emotion. Emotions the
model has no counterpart of (``relaxed``, ``surprised``, ``Fun``) stay at 0.
Mouth and face keys touch disjoint channels, so their blends are solved
independently.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from ..errors import ModelStoreError
from ..visemes import OCULUS15
from .probes import CLOSURE_CONTEXTS, RigProbe
from .retarget import KeyPosePairs
from .rig_names import (
    VRM0_CONTROLS,
    VRM0_MOUTH,
    VRM1_CONTROLS,
    VRM1_MOUTH,
    VROID_CONTROLS,
    VROID_MOUTH,
)

VOWELS = ("A", "I", "U", "E", "O")
VOWEL_KEYS: Mapping[str, Mapping[str, float]] = {
    "PP": {},
    "FF": {"I": 0.3},
    "TH": {"A": 0.2, "E": 0.3},
    "DD": {"A": 0.3, "I": 0.2},
    "kk": {"A": 0.4, "E": 0.2},
    "CH": {"I": 0.3, "U": 0.5},
    "SS": {"I": 0.6},
    "nn": {"A": 0.2, "E": 0.3},
    "RR": {"U": 0.3, "O": 0.3},
    "aa": {"A": 1.0},
    "E": {"E": 1.0},
    "I": {"I": 1.0},
    "O": {"O": 1.0},
    "U": {"U": 1.0},
}
"""Each Oculus viseme class (its phonemes: ``lipstream.visemes.OCULUS15``) as vowel
controls; a vowel not named is 0. ``PP`` (/p b m/) closes the mouth: every vowel 0."""
BLINK_CHANNELS = ("eyeBlinkLeft", "eyeBlinkRight")
_NEGLIGIBLE = 1e-6  # an emotion that moves no channel more than this is not shown


@dataclass(frozen=True)
class VowelRig:
    """A vowel-only rig's control names: its vowels in ``VOWELS`` order, blink, the emotions
    it has by the model's emotion names, and its neutral face."""

    controls: tuple[str, ...]
    vowels: tuple[str, ...]
    blink: str
    emotions: Mapping[str, str]
    neutral: str


VOWEL_RIGS: Mapping[str, VowelRig] = {
    "vrm1": VowelRig(
        VRM1_CONTROLS,
        VRM1_MOUTH,
        "blink",
        {"happy": "happy", "angry": "angry", "sad": "sad"},
        "neutral",
    ),
    "vrm0": VowelRig(
        VRM0_CONTROLS,
        VRM0_MOUTH,
        "Blink",
        {"happy": "Joy", "angry": "Angry", "sad": "Sorrow"},
        "Neutral",
    ),
    "vroid": VowelRig(
        VROID_CONTROLS,
        VROID_MOUTH,
        "Fcl_EYE_Close",
        {"happy": "Fcl_ALL_Joy", "angry": "Fcl_ALL_Angry", "sad": "Fcl_ALL_Sorrow"},
        "Fcl_ALL_Neutral",
    ),
}


Keys = list[tuple[str, np.ndarray, np.ndarray]]
"""(name, source pose, rig controls) of each key."""


def vowel_rig_pairs(rig: VowelRig, probe: RigProbe, mouth: np.ndarray) -> KeyPosePairs:
    """The key-pose pairs of ``rig`` for the probed model; ``mouth`` (n_channels,) bool marks
    its mouth channels."""
    rest = probe.silence
    poses = (rest, probe.viseme_poses, probe.closure_poses)
    if not all(np.isfinite(pose).all() for pose in poses):
        raise ModelStoreError("synthesizes NaN or infinite key poses", where="rig probe")
    control_rest = _controls(rig, {rig.neutral: 1.0})
    keys = _mouth_keys(rig, probe, mouth) + _face_keys(rig, probe, mouth)
    return KeyPosePairs(
        channels=probe.channels,
        controls=rig.controls,
        key_names=tuple(name for name, _, _ in keys),
        source_rest=rest,
        control_rest=control_rest,
        source_keys=np.stack([source for _, source, _ in keys]),
        control_keys=np.stack([controls for _, _, controls in keys]),
        channel_weights=np.ones(len(probe.channels)),
    )


def _mouth_keys(rig: VowelRig, probe: RigProbe, mouth: np.ndarray) -> Keys:
    """A key per ``VOWEL_KEYS`` viseme class, then a closed-mouth key per bilabial in context,
    each on the mouth channels only."""
    rest = probe.silence
    keys: Keys = []
    for viseme, vowels in VOWEL_KEYS.items():
        pose = probe.viseme_poses[OCULUS15.classes.index(viseme)]
        named = {rig.vowels[VOWELS.index(vowel)]: value for vowel, value in vowels.items()}
        controls = _controls(rig, {rig.neutral: 1.0} | named)
        keys.append((viseme, np.where(mouth, pose, rest), controls))
    closed = _controls(rig, {rig.neutral: 1.0})
    for context, pose in zip(CLOSURE_CONTEXTS, probe.closure_poses):
        keys.append((" ".join(context), np.where(mouth, pose, rest), closed))
    return keys


def _face_keys(rig: VowelRig, probe: RigProbe, mouth: np.ndarray) -> Keys:
    """Off the mouth: the blink, what each viseme class's pose does there (speech, so the
    rig's neutral face), then each emotion the model shows."""
    rest = probe.silence
    neutral = _controls(rig, {rig.neutral: 1.0})
    blink = [probe.channels.index(name) for name in BLINK_CHANNELS if name in probe.channels]
    keys: Keys = []
    if blink:
        closed_eyes = rest.copy()
        closed_eyes[blink] = 1.0
        keys.append(("blink", closed_eyes, _controls(rig, {rig.neutral: 1.0, rig.blink: 1.0})))
    for viseme in VOWEL_KEYS:
        face = np.where(mouth, rest, probe.viseme_poses[OCULUS15.classes.index(viseme)])
        face[blink] = rest[blink]
        if np.abs(face - rest).max(initial=0.0) > _NEGLIGIBLE:
            keys.append((f"{viseme} face", face, neutral))
    for emotion, control in rig.emotions.items():
        if emotion not in probe.rest_poses:
            continue
        delta = np.where(mouth, 0.0, probe.emotion_delta(emotion))
        if np.abs(delta).max(initial=0.0) > _NEGLIGIBLE:
            keys.append((emotion, rest + delta, _controls(rig, {control: 1.0})))
    return keys


def _controls(rig: VowelRig, values: Mapping[str, float]) -> np.ndarray:
    controls = np.zeros(len(rig.controls))
    for name, value in values.items():
        controls[rig.controls.index(name)] = value
    return controls
