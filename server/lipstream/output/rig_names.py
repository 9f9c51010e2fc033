"""The control names of the rigs lipstream ships presets for, as each rig's software spells them.

Sources (names only; no data is copied):

* VRM 1.0 expression presets: the VRM 1.0 specification (``VRMC_vrm``
  ``expressions.preset``), as in three-vrm's ``VRMExpressionPresetName``.
* VRM 0.x blend shape presets: UniVRM's ``BlendShapePreset`` (``A I U E O``,
  ``Blink``, ``Joy Angry Sorrow Fun``, ``Neutral``).
* VRoid Studio face morphs: the ``Fcl_*`` shape keys of a VRoid Studio export.
* Unified Expressions (VRCFaceTracking): the jaw, lip and mouth shapes of its
  ``UnifiedExpressions`` enum and documentation.
* Audio2Face-3D: the 52 face blendshapes in the order of NVIDIA's
  Audio2Face-3D-Samples configuration files (``weight_multipliers``), then the 16
  tongue blendshapes of its tongue solve.
* Live Link Face: the ARKit names with the first letter upper case (``JawOpen``).
"""

from __future__ import annotations

from lipstream_client.channels import rename_channel
from lipstream_client.sinks.livelink import LIVELINK_BLENDSHAPES as PACKET_BLENDSHAPES

from ..corpus.livelink import ARKIT_BLENDSHAPES
from ..tables import names

VRM1_MOUTH: tuple[str, ...] = ("aa", "ih", "ou", "ee", "oh")
VRM1_EMOTIONS: tuple[str, ...] = ("happy", "angry", "sad", "relaxed", "surprised")
VRM1_CONTROLS: tuple[str, ...] = (*VRM1_MOUTH, "blink", *VRM1_EMOTIONS, "neutral")

VRM0_MOUTH: tuple[str, ...] = ("A", "I", "U", "E", "O")
VRM0_EMOTIONS: tuple[str, ...] = ("Joy", "Angry", "Sorrow", "Fun")
VRM0_CONTROLS: tuple[str, ...] = (*VRM0_MOUTH, "Blink", *VRM0_EMOTIONS, "Neutral")

VROID_MOUTH: tuple[str, ...] = ("Fcl_MTH_A", "Fcl_MTH_I", "Fcl_MTH_U", "Fcl_MTH_E", "Fcl_MTH_O")
VROID_EMOTIONS: tuple[str, ...] = names(
    "Fcl_ALL_Joy Fcl_ALL_Angry Fcl_ALL_Sorrow Fcl_ALL_Fun Fcl_ALL_Surprised"
)
VROID_CONTROLS: tuple[str, ...] = (
    *VROID_MOUTH,
    "Fcl_EYE_Close",
    *VROID_EMOTIONS,
    "Fcl_ALL_Neutral",
)

UNIFIED_LIP_JAW: tuple[str, ...] = names("""
    JawOpen JawRight JawLeft JawForward MouthClosed
    LipSuckUpperRight LipSuckUpperLeft LipSuckLowerRight LipSuckLowerLeft
    LipFunnelUpperRight LipFunnelUpperLeft LipFunnelLowerRight LipFunnelLowerLeft
    LipPuckerUpperRight LipPuckerUpperLeft LipPuckerLowerRight LipPuckerLowerLeft
    MouthUpperUpRight MouthUpperUpLeft MouthLowerDownRight MouthLowerDownLeft
    MouthUpperRight MouthUpperLeft MouthLowerRight MouthLowerLeft
    MouthCornerPullRight MouthCornerPullLeft MouthCornerSlantRight MouthCornerSlantLeft
    MouthFrownRight MouthFrownLeft MouthStretchRight MouthStretchLeft
    MouthDimpleRight MouthDimpleLeft MouthRaiserUpper MouthRaiserLower
    MouthPressRight MouthPressLeft MouthTightenerRight MouthTightenerLeft
""")

UNIFIED_FROM_ARKIT: dict[str, tuple[str, ...]] = {
    "jawOpen": ("JawOpen",),
    "jawRight": ("JawRight",),
    "jawLeft": ("JawLeft",),
    "jawForward": ("JawForward",),
    "mouthClose": ("MouthClosed",),
    "mouthRollUpper": ("LipSuckUpperRight", "LipSuckUpperLeft"),
    "mouthRollLower": ("LipSuckLowerRight", "LipSuckLowerLeft"),
    "mouthFunnel": (
        "LipFunnelUpperRight",
        "LipFunnelUpperLeft",
        "LipFunnelLowerRight",
        "LipFunnelLowerLeft",
    ),
    "mouthPucker": (
        "LipPuckerUpperRight",
        "LipPuckerUpperLeft",
        "LipPuckerLowerRight",
        "LipPuckerLowerLeft",
    ),
    "mouthUpperUpRight": ("MouthUpperUpRight",),
    "mouthUpperUpLeft": ("MouthUpperUpLeft",),
    "mouthLowerDownRight": ("MouthLowerDownRight",),
    "mouthLowerDownLeft": ("MouthLowerDownLeft",),
    "mouthRight": ("MouthUpperRight", "MouthLowerRight"),
    "mouthLeft": ("MouthUpperLeft", "MouthLowerLeft"),
    "mouthSmileRight": ("MouthCornerPullRight", "MouthCornerSlantRight"),
    "mouthSmileLeft": ("MouthCornerPullLeft", "MouthCornerSlantLeft"),
    "mouthFrownRight": ("MouthFrownRight",),
    "mouthFrownLeft": ("MouthFrownLeft",),
    "mouthStretchRight": ("MouthStretchRight",),
    "mouthStretchLeft": ("MouthStretchLeft",),
    "mouthDimpleRight": ("MouthDimpleRight",),
    "mouthDimpleLeft": ("MouthDimpleLeft",),
    "mouthShrugUpper": ("MouthRaiserUpper",),
    "mouthShrugLower": ("MouthRaiserLower",),
    "mouthPressRight": ("MouthPressRight",),
    "mouthPressLeft": ("MouthPressLeft",),
}
"""Each ARKit mouth or jaw shape as Unified Expressions shapes (VRCFaceTracking's ARKit
transform): a symmetric ARKit shape drives each side's part at the same value. The
``MouthTightener`` shapes have no ARKit source."""

LIVELINK_BLENDSHAPES: tuple[str, ...] = tuple(
    rename_channel(name, "livelink") for name in ARKIT_BLENDSHAPES
)

A2F_FACE: tuple[str, ...] = tuple(rename_channel(name, "livelink") for name in PACKET_BLENDSHAPES)
"""Audio2Face-3D's 52 face shapes: ARKit's in the Live Link packet's order, PascalCase."""
A2F_TONGUE: tuple[str, ...] = names("""
    TongueTipUp TongueTipDown TongueTipLeft TongueTipRight
    TongueRollUp TongueRollDown TongueRollLeft TongueRollRight
    TongueUp TongueDown TongueLeft TongueRight
    TongueIn TongueStretch TongueWide TongueNarrow
""")
A2F68: tuple[str, ...] = A2F_FACE + A2F_TONGUE
