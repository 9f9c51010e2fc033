"""Rig presets with a control per Oculus viseme: oculus15, and rpm (Ready Player Me, Avaturn).

Sketch: the rig has one control per Oculus viseme (``viseme_sil`` …
``viseme_U``), each showing its viseme class's key pose, probed from the
model (``RigProbe.viseme_poses``). Rest is silence: its pose is the silence
key pose and its controls are ``viseme_sil`` = 1. The 14 other visemes are
the keys; their controls are fitted on the rig's transfer (each viseme
control drives its key pose; ``fit_controls``) and come out one-hot when
the key poses are independent. Each bilabial probed in context
(``probes.CLOSURE_CONTEXTS``: lips closed, but rounded or spread as the
vowels around them) is one more key with ``viseme_PP``'s controls, so a
coarticulated closure reads as ``viseme_PP``. Only the mouth channels are
fitted.

``rpm`` is the avatar of Ready Player Me and Avaturn, which carries both the
15 ``viseme_*`` morph targets and Apple's 52 ARKit ones: the visemes show the
mouth as in ``oculus15`` (key poses on the mouth channels only), and each
ARKit channel of the model off the mouth (blinks, brows, squints) passes
through to its ARKit morph. The ARKit mouth morphs are held at 0, so the
mouth is not shown twice over (a viseme and its ARKit shapes together).
"""

from __future__ import annotations

import numpy as np

from lipstream_client.channels import OCULUS15_VISEMES

from ..corpus.livelink import ARKIT_BLENDSHAPES
from ..errors import ModelStoreError
from ..visemes import OCULUS15
from .probes import CLOSURE_CONTEXTS, RigProbe
from .retarget import KeyPosePairs, fit_controls

RPM_CONTROLS: tuple[str, ...] = OCULUS15_VISEMES + ARKIT_BLENDSHAPES


def oculus15_pairs(probe: RigProbe, mouth: np.ndarray) -> KeyPosePairs:
    """The ``oculus15`` key-pose pairs of the probed model; ``mouth`` (n_channels,) bool marks
    the fitted channels."""
    poses = probe.viseme_poses
    if not (np.isfinite(poses).all() and np.isfinite(probe.closure_poses).all()):
        raise ModelStoreError("synthesizes NaN or infinite viseme key poses", where="viseme probe")
    silence = OCULUS15.classes.index("sil")
    weights = mouth.astype(np.float64)
    keys = [index for index in range(len(poses)) if index != silence]
    control_keys = np.stack(
        [fit_controls(poses, poses[silence], poses[index], weights) for index in keys]
    )
    closed = control_keys[keys.index(OCULUS15.classes.index("PP"))]
    closures = np.where(mouth, probe.closure_poses, poses[silence])
    return KeyPosePairs(
        channels=probe.channels,
        controls=OCULUS15_VISEMES,
        key_names=tuple(OCULUS15_VISEMES[index] for index in keys)
        + tuple(" ".join(context) for context in CLOSURE_CONTEXTS),
        source_rest=poses[silence],
        control_rest=np.eye(len(poses))[silence],
        source_keys=np.vstack([poses[keys], closures]),
        control_keys=np.vstack([control_keys, np.tile(closed, (len(closures), 1))]),
        channel_weights=weights,
    )


def rpm_pairs(probe: RigProbe, mouth: np.ndarray) -> KeyPosePairs:
    """The ``rpm`` key-pose pairs: ``oculus15``'s viseme keys restricted to the mouth channels,
    then one key per ARKit channel off the mouth."""
    visemes = oculus15_pairs(probe, mouth)
    channels = probe.channels
    rest = np.where(mouth, visemes.source_rest, 0.0)
    face = [
        index
        for index, name in enumerate(channels)
        if name in ARKIT_BLENDSHAPES and not mouth[index]
    ]
    face_keys = np.tile(rest, (len(face), 1))
    face_controls = np.zeros((len(face), len(RPM_CONTROLS)))
    for row, index in enumerate(face):
        face_keys[row, index] = 1.0
        face_controls[row, len(OCULUS15_VISEMES) + ARKIT_BLENDSHAPES.index(channels[index])] = 1.0
    viseme_controls = np.zeros((len(visemes.key_names), len(RPM_CONTROLS)))
    viseme_controls[:, : len(OCULUS15_VISEMES)] = visemes.control_keys
    control_rest = np.zeros(len(RPM_CONTROLS))
    control_rest[: len(OCULUS15_VISEMES)] = visemes.control_rest
    weights = np.where(mouth, 1.0, 0.0)
    weights[face] = 1.0
    return KeyPosePairs(
        channels=channels,
        controls=RPM_CONTROLS,
        key_names=visemes.key_names + tuple(channels[index] for index in face),
        source_rest=rest,
        control_rest=control_rest,
        source_keys=np.vstack([np.where(mouth, visemes.source_keys, 0.0), face_keys]),
        control_keys=np.vstack([viseme_controls, face_controls]),
        channel_weights=weights,
    )
