"""Rig presets for blendshape rigs named after ARKit: arkit52, metahuman, a2f68, unified.

Sketch: these rigs have a control for (a part of) each ARKit blendshape, so
their transfer from the model's ARKit-named channels is a published name
correspondence, not a fit. Rest is the neutral face (every channel and
control 0) and there is one key per model channel the rig has a
counterpart of: that channel at 1, and its counterparts at 1
(``drives``). Each key moves one channel of its own, so the map passes each
such channel through to its counterparts, clipped to [0, 1]; a control no
model channel drives (a shape the model lacks, the Audio2Face tongue) is
held at rest, 0.

* ``arkit52``: Apple's 52 blendshapes, in Apple's order.
* ``metahuman``: the same 52 as Unreal Live Link Face names its curves
  (``JawOpen``), which a MetaHuman's ARKit pose asset reads.
* ``a2f68``: Audio2Face-3D's 68: its 52 face blendshapes in its own order and
  its 16 tongue blendshapes, each driven by the model channel of the same name
  with the first letter lower case (``tongueTipUp``), at rest for a model
  without it.
* ``unified``: the Unified Expressions (VRCFaceTracking) jaw, lip and mouth
  shapes, each ARKit mouth shape driving its parts (``UNIFIED_FROM_ARKIT``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from ..corpus.livelink import ARKIT_BLENDSHAPES
from ..errors import ModelStoreError
from .retarget import KeyPosePairs
from .rig_names import A2F68, LIVELINK_BLENDSHAPES, UNIFIED_FROM_ARKIT, UNIFIED_LIP_JAW


def _renamed(controls: Sequence[str]) -> dict[str, tuple[str, ...]]:
    """Model channel -> the one control of the same shape: each control under its ARKit-style
    name, the first letter lower case (``JawOpen`` is driven by ``jawOpen``, ``TongueTipUp``
    by ``tongueTipUp``)."""
    return {control[:1].lower() + control[1:]: (control,) for control in controls}


BLENDSHAPE_RIGS: Mapping[str, tuple[tuple[str, ...], Mapping[str, tuple[str, ...]]]] = {
    "arkit52": (ARKIT_BLENDSHAPES, {name: (name,) for name in ARKIT_BLENDSHAPES}),
    "metahuman": (LIVELINK_BLENDSHAPES, _renamed(LIVELINK_BLENDSHAPES)),
    "a2f68": (A2F68, _renamed(A2F68)),
    "unified": (UNIFIED_LIP_JAW, UNIFIED_FROM_ARKIT),
}
"""Each rig's controls, and the controls each ARKit channel drives."""


def blendshape_rig_pairs(
    name: str,
    controls: tuple[str, ...],
    drives: Mapping[str, tuple[str, ...]],
    channels: Sequence[str],
) -> KeyPosePairs:
    """The key-pose pairs of rig ``name`` for a model with ``channels``."""
    shared = [index for index, channel in enumerate(channels) if channel in drives]
    if not shared:
        raise ModelStoreError(
            f"the model has no channel with an ARKit name to map onto {name}", where="channels"
        )
    control_keys = np.zeros((len(shared), len(controls)))
    for row, index in enumerate(shared):
        for control in drives[channels[index]]:
            control_keys[row, controls.index(control)] = 1.0
    return KeyPosePairs(
        channels=tuple(channels),
        controls=controls,
        key_names=tuple(channels[index] for index in shared),
        source_rest=np.zeros(len(channels)),
        control_rest=np.zeros(len(controls)),
        source_keys=np.eye(len(channels))[shared],
        control_keys=control_keys,
        channel_weights=np.ones(len(channels)),
    )
