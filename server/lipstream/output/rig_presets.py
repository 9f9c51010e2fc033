"""The shipped rig presets: retarget maps built from any model, picked in ``output.retarget``.

Sketch: a preset is a rig (its control names, documented with their
sources in ``rig_names``) and the rule that builds its key-pose pairs from a
model (``vowel_rigs``, ``viseme_rigs``, ``blendshape_rigs``); the pairs are
fitted into a ``RetargetMap`` like any stored map. The server builds every
preset a model is offered at start-up, from one probe of the model
(``RigProbe``); the command line builds the one it is asked for. A preset
built on ARKit names is offered only to a model with some ARKit channel name.
Clients find the names in ``lipstream_client.channels.RETARGET_PRESETS``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import numpy as np

from lipstream_client.channels import OCULUS15_VISEMES
from lipstream_client.errors import UNKNOWN_RETARGET

from ..corpus.livelink import ARKIT_BLENDSHAPES
from ..engines.base import Model
from ..errors import LipstreamError
from .blendshape_rigs import BLENDSHAPE_RIGS, blendshape_rig_pairs
from .probes import RigProbe, mouth_channels, probe_rig
from .retarget import KeyPosePairs, RetargetMap, fit_map, stored_maps
from .viseme_rigs import RPM_CONTROLS, oculus15_pairs, rpm_pairs
from .vowel_rigs import VOWEL_RIGS, vowel_rig_pairs

ProbeSource = Callable[[], RigProbe]
Builder = Callable[[tuple[str, ...], ProbeSource], KeyPosePairs]
"""Key-pose pairs for a model's channels; the probe is called only when the key poses are
the model's own."""


@dataclass(frozen=True)
class RigPreset:
    """A shipped preset: ``rig`` says which rig it drives; ``controls`` are its output names;
    ``needs_arkit`` offers it only to models with ARKit channel names."""

    name: str
    rig: str
    controls: tuple[str, ...]
    needs_arkit: bool
    build: Builder


def _blendshape(name: str) -> Builder:
    controls, drives = BLENDSHAPE_RIGS[name]
    return lambda channels, _: blendshape_rig_pairs(name, controls, drives, channels)


def _vowel(name: str) -> Builder:
    return lambda channels, probe: vowel_rig_pairs(
        VOWEL_RIGS[name], probe(), mouth_channels(channels)
    )


def _probed(pairs: Callable[[RigProbe, np.ndarray], KeyPosePairs]) -> Builder:
    return lambda channels, probe: pairs(probe(), mouth_channels(channels))


PRESETS: Mapping[str, RigPreset] = {
    preset.name: preset
    for preset in (
        RigPreset(
            "oculus15",
            "the 15 Oculus visemes (OVR LipSync, XR_META_face_tracking_visemes)",
            OCULUS15_VISEMES,
            False,
            _probed(oculus15_pairs),
        ),
        RigPreset(
            "arkit52",
            "Apple's 52 ARKit blendshapes",
            ARKIT_BLENDSHAPES,
            True,
            _blendshape("arkit52"),
        ),
        RigPreset(
            "vrm1", "VRM 1.0 expression presets", VOWEL_RIGS["vrm1"].controls, False, _vowel("vrm1")
        ),
        RigPreset(
            "vrm0",
            "VRM 0.x blend shape presets",
            VOWEL_RIGS["vrm0"].controls,
            False,
            _vowel("vrm0"),
        ),
        RigPreset(
            "vroid",
            "VRoid Studio Fcl_* face morphs",
            VOWEL_RIGS["vroid"].controls,
            False,
            _vowel("vroid"),
        ),
        RigPreset(
            "rpm",
            "Ready Player Me / Avaturn: viseme_* and ARKit morphs",
            RPM_CONTROLS,
            False,
            _probed(rpm_pairs),
        ),
        RigPreset(
            "unified",
            "Unified Expressions (VRCFaceTracking) jaw, lip and mouth shapes",
            BLENDSHAPE_RIGS["unified"][0],
            True,
            _blendshape("unified"),
        ),
        RigPreset(
            "metahuman",
            "MetaHuman through Live Link Face's ARKit curves (PascalCase)",
            BLENDSHAPE_RIGS["metahuman"][0],
            True,
            _blendshape("metahuman"),
        ),
        RigPreset(
            "a2f68",
            "Audio2Face-3D's 52 face and 16 tongue blendshapes",
            BLENDSHAPE_RIGS["a2f68"][0],
            True,
            _blendshape("a2f68"),
        ),
    )
}


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
    return preset(name, "target").build(tuple(model.channels), _probe_source(model, probe))


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
            maps[name] = fit_map(name, PRESETS[name].build(tuple(model.channels), source))
    return maps | stored


def _probe_source(model: Model, probe: RigProbe | None) -> ProbeSource:
    if probe is not None:
        return lambda: probe
    return cache(lambda: probe_rig(model))
