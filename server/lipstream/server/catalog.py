"""The resident models and what the server derives from them once, at start-up.

Sketch: the ``Catalog`` wraps the ``ModelRegistry`` and precomputes, per
model, the latency estimate of every fidelity rung (``budget``,
``calibration``), the rest pose for each emotion (the frame in the middle of
one second of silence), the retarget maps it can be served through (every
rig preset it is offered, ``lipstream.output.rig_presets``, fitted on its
phoneme and rest probes, and the maps stored in its directory), and, per
character, the viseme projectors (one per output viseme set), the preset
output profile and the default emotion. Each model is warmed up first (its
first calls compile or load its kernels) and then calibrated; ``build``
reports both steps through ``report`` when given.
Start-up is bounded per model (``calibration``): a model whose probes, warm-up and
calibration use more than ``calibration_cpu_s`` of the injectable ``clock``, or whose rung
would need more than ``max_model_session_cost`` of a core per session, is
dropped (``model_too_costly``) before its cost reaches admission, and the others
are served. Calibration also probes every rung: a non-finite frame drops the model
with ``model_invalid`` (``calibration.check_frames``). After ``build`` it is read-only,
so sessions on the event loop and in the synthesis thread pool share it without locks.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from lipstream_client import OutputProfile
from lipstream_client.errors import INVALID_REQUEST, UNKNOWN_CHARACTER, UNKNOWN_ENGINE

from ..config import ServerSettings
from ..engines.base import CallCost, Model, Rung
from ..engines.work import WorkGuard
from ..errors import LipstreamError, ModelStoreError
from ..frontends.word_durations import WordDurationModel
from ..models import ModelRegistry
from ..numerics.nnls import warm_nnls
from ..output.probes import RigProbe, probe_closures, probe_phoneme_poses, probe_rest_poses
from ..output.profiles import (
    ProfileError,
    ProfileRequest,
    load_default_emotions,
    load_presets,
    parse_profile,
    resolve_profile,
)
from ..output.retarget import RetargetMap
from ..output.rig_presets import model_maps
from ..output.viseme_projection import VisemeProjector, projectors_from
from ..status import Report, phase
from ..store import MANIFEST_NAME
from ..timeline import EMOTIONS
from .budget import RungEstimate, estimate
from .calibration import calibration_guard, measure, warm_up

logger = logging.getLogger("lipstream.server")

PRESET_KEY = "output_profile"
_VISEME_SOURCE_ENGINE = "viseme-lerp"


class CatalogError(LipstreamError):
    """No loaded model answers a request (``unknown_engine`` or ``unknown_character``)."""

    code = UNKNOWN_ENGINE


@dataclass
class ModelFacts:
    """What the server derived from one model at start-up."""

    ladder: tuple[RungEstimate, ...]
    rest: dict[str | None, np.ndarray]
    projectors: dict[str, VisemeProjector]
    retargets: dict[str, RetargetMap]


@dataclass
class Catalog:
    """Resident models, their latency ladders, rest poses, viseme projectors and presets."""

    registry: ModelRegistry
    settings: ServerSettings
    facts: dict[int, ModelFacts] = field(default_factory=dict)
    presets: dict[str, OutputProfile] = field(default_factory=dict)
    default_emotions: dict[str, str] = field(default_factory=dict)
    durations: dict[int, WordDurationModel] = field(default_factory=dict)

    @classmethod
    def build(
        cls,
        registry: ModelRegistry,
        settings: ServerSettings,
        report: Report | None = None,
        clock: Callable[[], float] = time.thread_time,
    ) -> Catalog:
        """Measure and probe every model, reporting each step to ``report``; a model whose
        probes or stored preset fail, or whose calibration is out of range (its bound runs
        on ``clock``, by default this thread's CPU time), is dropped from ``registry`` (see
        ``ModelRegistry.require_models`` for when that raises); LipstreamError for a preset
        from ``settings`` that does not fit."""
        catalog = cls(registry, settings)
        probed: dict[int, tuple[dict[str, VisemeProjector], dict[str, np.ndarray]]] = {}
        for name, model in list(registry.models.items()):
            where = str(registry.directories.get(name, Path(name)))
            guard = calibration_guard(settings.calibration_cpu_s, f"{where}: calibration", clock)
            try:
                with guard.metering():
                    source = _viseme_source(registry, model)
                    if id(source) not in probed:
                        poses = probe_phoneme_poses(source, guard)
                        probed[id(source)] = (projectors_from(poses, source.channels), poses)
                    projectors, phoneme_poses = probed[id(source)]
                    rest = probe_rest_poses(model, guard)
                    emotion_rests = {emotion: rest[emotion] for emotion in EMOTIONS}
                    closures = probe_closures(model, guard)
                    probe = RigProbe(model.channels, phoneme_poses, emotion_rests, closures)
                    retargets = model_maps(model, registry.directories.get(name), probe=probe)
                    ladder = catalog._ladder(where, model, guard, report)
                catalog.facts[id(model)] = ModelFacts(ladder, rest, projectors, retargets)
            except LipstreamError as error:
                registry.drop(name, error)
            except Exception as error:  # a fault in one model's probe must not stop the rest
                logger.exception("probing model %s failed", name)
                fault = f"its start-up probe failed ({type(error).__name__}: {error})"
                registry.drop(name, ModelStoreError(fault, where=name))
        warm_nnls()  # the retarget maps' kernel, before a stream's first frame needs it
        catalog.presets = _presets(registry, settings)
        registry.require_models(strict=settings.strict_models)
        if settings.profiles is not None:
            catalog.default_emotions = load_default_emotions(settings.profiles)
        catalog._check_presets()
        return catalog

    @property
    def engines(self) -> set[str]:
        return {model.manifest.engine for model in self.registry.models.values()}

    def model(self, engine: str, character: str) -> Model:
        """The model serving ``character`` with ``engine``; CatalogError naming the field."""
        if engine not in self.engines:
            raise CatalogError(
                f"no engine {engine!r} is loaded; loaded: {', '.join(sorted(self.engines))}",
                where="engine",
            )
        for model in self.registry.models.values():
            if model.manifest.engine == engine and model.name == character:
                return model
        served = sorted(
            model.name for model in self.registry.models.values() if model.manifest.engine == engine
        )
        raise CatalogError(
            f"no character {character!r} for engine {engine!r}; it serves {', '.join(served)}",
            where="character",
            code=UNKNOWN_CHARACTER,
        )

    def word_durations(self, engine: str, character: str) -> WordDurationModel:
        """The duration model stored beside the model of ``engine`` and ``character``
        (read once); ``invalid_request`` naming the model when it has none or it is
        damaged."""
        model = self.model(engine, character)
        found = self.durations.get(id(model))
        if found is not None:
            return found
        name = next(name for name, served in self.registry.models.items() if served is model)
        directory = self.registry.directories.get(name)
        try:
            if directory is None:
                raise ModelStoreError("the model has no directory", where=name)
            found = WordDurationModel.load(directory)
        except ModelStoreError as error:
            raise LipstreamError(
                f"model {name!r} cannot read word timings: {error.message}",
                where=error.where,
                code=INVALID_REQUEST,
            ) from None
        self.durations[id(model)] = found
        return found

    def ladder(self, model: Model) -> tuple[RungEstimate, ...]:
        return self.facts[id(model)].ladder

    def call_cost(self, model: Model, options: Mapping[str, Any]) -> CallCost:
        """The engine's estimate of one streaming call with ``options``, from the costs
        calibration measured for its rungs."""
        measured = {estimate.rung.name: estimate.call_cost for estimate in self.ladder(model)}
        return model.call_cost(options, measured)

    def rest_pose(self, model: Model, emotion: str | None) -> np.ndarray:
        """The model's face at rest, float32 (n_channels,)."""
        return self.facts[id(model)].rest[emotion]

    def projector(self, model: Model, visemes: str = "oculus15") -> VisemeProjector:
        """The projector of ``model``'s frames onto the viseme set ``visemes``."""
        return self.facts[id(model)].projectors[visemes]

    def retargets(self, model: Model) -> dict[str, RetargetMap]:
        """The retarget maps ``model`` can be served through, by name."""
        return self.facts[id(model)].retargets

    def _projector_of(self, model: Model) -> Callable[[str], VisemeProjector]:
        return lambda visemes: self.projector(model, visemes)

    def preset(self, character: str) -> OutputProfile | None:
        return self.presets.get(character)

    def default_emotion(self, model: Model) -> str:
        """The emotion of a request that names none: the character's preset's
        ``default_emotion``, else the model's (``Model.default_emotion``)."""
        return self.default_emotions.get(model.name, model.default_emotion)

    def _ladder(
        self, where: str, model: Model, guard: WorkGuard, report: Report | None
    ) -> tuple[RungEstimate, ...]:
        """The model (stored at ``where``) warmed up and its rungs calibrated, under
        ``guard`` (``calibration_guard``, metered by the caller): ``ModelCostError`` naming
        the model's directory and the rung when out of bounds."""
        ladder = model.fidelity_ladder()
        label = f"{model.manifest.engine} ({model.name})"
        with phase(f"warming up {label}", report):
            warm_up(model, ladder[0], guard, where)
        rungs = []
        with phase(f"calibrating {label}: timing {len(ladder)} fidelity rung(s)", report):
            for rung in ladder:
                rungs.append(self._rung(where, model, rung, guard))
        return tuple(rungs)

    def _rung(self, where: str, model: Model, rung: Rung, guard: WorkGuard) -> RungEstimate:
        settings = self.settings
        cost = measure(model, rung, guard, settings.max_model_session_cost, where)
        return estimate(
            rung,
            settings.max_phoneme_ms,
            cost.max_call_ms,
            settings.compute_margin_ms,
            cost.call_cost,
        )

    def _check_presets(self) -> None:
        for character, preset in self.presets.items():
            for model in self.registry.models.values():
                if model.name != character:
                    continue
                try:
                    resolve_profile(
                        model.channels,
                        ProfileRequest(preset, "preset"),
                        self._projector_of(model),
                        self.retargets(model),
                    )
                except ProfileError as error:
                    raise LipstreamError(
                        f"the preset output profile of {character!r} does not fit "
                        f"{model.manifest.engine}: {error}",
                        where=PRESET_KEY,
                        code="invalid_setting",
                    ) from None


def warm_kernels(model: Model) -> None:
    """Make the calls that compile ``model``'s kernels at start-up (its rest poses, the viseme
    probe, every rung's calibration stream), timing nothing: run in another process, they
    leave the compiled kernels in numba's on-disk cache for the server to load."""
    warm_nnls()
    probe_rest_poses(model)
    probe_phoneme_poses(model)
    probe_closures(model)
    for rung in model.fidelity_ladder():
        warm_up(model, rung)


def _viseme_source(registry: ModelRegistry, model: Model) -> Model:
    """The model whose key poses define ``model``'s visemes: the character's viseme-lerp model
    with the same channels if one is loaded, else ``model`` itself."""
    return next(
        (
            other
            for other in registry.models.values()
            if other.manifest.engine == _VISEME_SOURCE_ENGINE
            and other.name == model.name
            and other.channels == model.channels
        ),
        model,
    )


def _presets(registry: ModelRegistry, settings: ServerSettings) -> dict[str, OutputProfile]:
    """Presets stored in the models (a model whose preset does not parse is dropped), then
    those of ``settings.profiles``."""
    presets: dict[str, OutputProfile] = {}
    for name, model in list(registry.models.items()):
        value = model.manifest.extra.get(PRESET_KEY)
        if value is not None:
            manifest = registry.directories.get(name, Path(name)) / MANIFEST_NAME
            where = f"{manifest}: extra.{PRESET_KEY}"
            try:
                presets[model.name] = parse_profile(value, where)
            except LipstreamError as error:
                registry.drop(name, ModelStoreError(error.message, where=error.where))
    if settings.profiles is not None:
        presets.update(load_presets(settings.profiles))
    return presets
