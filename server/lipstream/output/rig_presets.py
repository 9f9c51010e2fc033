"""The shipped rig presets: retarget maps built from any model, picked in ``output.retarget``.

Sketch: a preset is a rig (its control names, documented with their
sources in ``rig_names``) and the rule that builds its key-pose pairs from a
model (``vowel_rigs``, ``viseme_rigs``, ``blendshape_rigs``); the pairs are
fitted into a ``RetargetMap`` like any stored map. The server builds every
preset a model is offered at start-up, from one probe of the model
(``RigProbe``); the command line builds the one it is asked for. A preset
built on ARKit names is offered only to a model with some ARKit channel name.
The names are also ``lipstream_client.channels.RETARGET_PRESETS``, for clients.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path

from lipstream_client.channels import OCULUS15_VISEMES, RETARGET_PRESETS
from lipstream_client.errors import UNKNOWN_RETARGET

from ..corpus.livelink import ARKIT_BLENDSHAPES
from ..engines.base import Model
from ..errors import LipstreamError
from .blendshape_rigs import BLENDSHAPE_RIGS, blendshape_rig_pairs
from .retarget import KeyPosePairs, RetargetMap, fit_map, stored_maps
from .rig_probe import RigProbe, probe_rig
from .viseme_rigs import RPM_CONTROLS, oculus15_pairs, rpm_pairs
from .vowel_rigs import VOWEL_RIGS, vowel_rig_pairs

ProbeSource = Callable[[], RigProbe]


@dataclass(frozen=True)
class RigPreset:
    """A shipped preset: ``rig`` says which rig it drives; ``controls`` are its output names;
    ``needs_arkit`` offers it only to models with ARKit channel names."""

    name: str
    rig: str
    controls: tuple[str, ...]
    needs_arkit: bool

    def pairs(self, channels: tuple[str, ...], probe: ProbeSource) -> KeyPosePairs:
        """The key-pose pairs of this preset for a model with ``channels``; ``probe`` is called
        only by presets whose key poses come from the model's own poses."""
        if self.name in BLENDSHAPE_RIGS:
            controls, drives = BLENDSHAPE_RIGS[self.name]
            return blendshape_rig_pairs(self.name, controls, drives, channels)
        from ..server.viseme_projection import mouth_channels

        mouth = mouth_channels(channels)
        if self.name in VOWEL_RIGS:
            return vowel_rig_pairs(VOWEL_RIGS[self.name], probe(), mouth)
        if self.name == "rpm":
            return rpm_pairs(probe(), mouth)
        return oculus15_pairs(probe(), mouth)


PRESETS: Mapping[str, RigPreset] = {
    preset.name: preset
    for preset in (
        RigPreset("oculus15", "the 15 Oculus visemes (OVR LipSync, XR_META_face_tracking_visemes)",
                  OCULUS15_VISEMES, False),
        RigPreset("arkit52", "Apple's 52 ARKit blendshapes", ARKIT_BLENDSHAPES, True),
        RigPreset("vrm1", "VRM 1.0 expression presets", VOWEL_RIGS["vrm1"].controls, False),
        RigPreset("vrm0", "VRM 0.x blend shape presets", VOWEL_RIGS["vrm0"].controls, False),
        RigPreset("vroid", "VRoid Studio Fcl_* face morphs", VOWEL_RIGS["vroid"].controls, False),
        RigPreset("rpm", "Ready Player Me / Avaturn: viseme_* and ARKit morphs", RPM_CONTROLS,
                  False),
        RigPreset("unified", "Unified Expressions (VRCFaceTracking) jaw, lip and mouth shapes",
                  BLENDSHAPE_RIGS["unified"][0], True),
        RigPreset("metahuman", "MetaHuman through Live Link Face's ARKit curves (PascalCase)",
                  BLENDSHAPE_RIGS["metahuman"][0], True),
        RigPreset("a2f68", "Audio2Face-3D's 52 face and 16 tongue blendshapes",
                  BLENDSHAPE_RIGS["a2f68"][0], True),
    )
}  # fmt: skip
assert tuple(PRESETS) == RETARGET_PRESETS


def offered_presets(channels: Sequence[str]) -> tuple[str, ...]:
    """The presets a model with ``channels`` is served through: those built on ARKit names only
    when some channel has an ARKit name."""
    arkit = any(name in ARKIT_BLENDSHAPES for name in channels)
    return tuple(name for name, preset in PRESETS.items() if arkit or not preset.needs_arkit)


def preset(name: str, where: str = "preset") -> RigPreset:
    """The preset called ``name``; ``unknown_retarget`` listing the presets otherwise."""
    found = PRESETS.get(name)
    if found is None:
        raise LipstreamError(
            f"no rig preset {name!r}; the presets: {', '.join(PRESETS)}",
            where=where,
            code=UNKNOWN_RETARGET,
        )
    return found


def preset_pairs(model: Model, name: str, probe: RigProbe | None = None) -> KeyPosePairs:
    """The key-pose pairs of preset ``name`` for ``model``, probing it if ``probe`` is None."""
    return preset(name, "target").pairs(tuple(model.channels), _probe_source(model, probe))


def model_maps(
    model: Model,
    directory: Path | None,
    *,
    probe: RigProbe | None = None,
    only: str | None = None,
) -> dict[str, RetargetMap]:
    """The maps ``model`` is served through, by name: the presets it is offered (with
    ``only``, just that one; built in ``PRESETS`` order), then those stored in
    ``directory/retarget/``; a stored map replaces a preset of the same name in its place."""
    stored = stored_maps(directory, model.channels) if directory is not None else {}
    source = _probe_source(model, probe)
    maps: dict[str, RetargetMap] = {}
    for name in offered_presets(model.channels):
        if name in stored:
            maps[name] = stored[name]
        elif only in (None, name):
            maps[name] = fit_map(name, PRESETS[name].pairs(tuple(model.channels), source))
    return maps | stored


def _probe_source(model: Model, probe: RigProbe | None) -> ProbeSource:
    if probe is not None:
        return lambda: probe
    return cache(lambda: probe_rig(model))
