"""The catalog's start-up probes set a model aside when it fails them, and serve the rest."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pytest

from lipstream.config import ServerSettings
from lipstream.engines.viseme_lerp import VisemeLerpModel
from lipstream.errors import LipstreamError, ModelStoreError
from lipstream.models import ModelRegistry
from lipstream.server.catalog import Catalog

if TYPE_CHECKING:
    from lipstream.engines.base import Model


def _registry(good: Model, broken: Model) -> ModelRegistry:
    return ModelRegistry(
        models={"good": good, "broken": broken},
        directories={"good": Path("/m/good"), "broken": Path("/m/broken")},
        root=Path("/m"),
    )


def _nan_model(lerp: VisemeLerpModel) -> VisemeLerpModel:
    """Built in memory, past the load-time checks, as a model the checks missed would be."""
    manifest = replace(lerp.manifest, name="broken")
    return VisemeLerpModel(
        manifest, lerp.poses * np.nan, lerp.durations, lerp.leads_ms, lerp.kappas
    )


def test_a_model_synthesizing_non_finite_silence_is_set_aside(
    trained_models: dict[str, Model],
) -> None:
    lerp = trained_models["viseme-lerp"]
    assert isinstance(lerp, VisemeLerpModel)
    registry = _registry(lerp, _nan_model(lerp))
    catalog = Catalog.build(registry, ServerSettings())
    assert list(registry.models) == ["good"]
    (failure,) = registry.failure_report()
    assert failure["model"] == "broken" and failure["character"] == "broken"
    assert failure["code"] == "model_invalid"
    assert failure["message"].startswith("synthesizes NaN or infinite frames for silence")
    assert np.isfinite(catalog.rest_pose(lerp, None)).all()


def test_strict_models_makes_a_failed_probe_fatal(trained_models: dict[str, Model]) -> None:
    lerp = trained_models["viseme-lerp"]
    assert isinstance(lerp, VisemeLerpModel)
    with pytest.raises(ModelStoreError, match="synthesizes NaN"):
        Catalog.build(_registry(lerp, _nan_model(lerp)), ServerSettings(strict_models=True))


def test_a_stored_preset_that_does_not_parse_sets_its_model_aside(
    trained_models: dict[str, Model],
) -> None:
    lerp = trained_models["viseme-lerp"]
    assert isinstance(lerp, VisemeLerpModel)
    manifest = replace(
        lerp.manifest, name="broken", extra={"output_profile": {"channels": "jawOpen"}}
    )
    registry = _registry(
        lerp, VisemeLerpModel(manifest, lerp.poses, lerp.durations, lerp.leads_ms, lerp.kappas)
    )
    Catalog.build(registry, ServerSettings())
    assert list(registry.models) == ["good"]
    error = registry.failures["broken"].error
    assert (error.code, error.where) == (
        "model_invalid",
        "/m/broken/model.json: extra.output_profile",
    )
    assert registry.failure_report()[0]["where"] == "broken/model.json: extra.output_profile"


def test_when_every_model_fails_its_probes_the_catalog_raises(
    trained_models: dict[str, Model],
) -> None:
    lerp = trained_models["viseme-lerp"]
    assert isinstance(lerp, VisemeLerpModel)
    registry = ModelRegistry(models={"broken": _nan_model(lerp)}, root=Path("/m"))
    with pytest.raises(LipstreamError, match="no model could be loaded") as caught:
        Catalog.build(registry, ServerSettings())
    assert caught.value.where == "/m"


class _FaultyModel(VisemeLerpModel):
    """A model whose synthesis raises something other than a LipstreamError."""

    def render(self, *args: object, **kwargs: object) -> np.ndarray:
        raise ZeroDivisionError("a fault inside the engine")


def test_an_unexpected_fault_in_a_probe_sets_only_that_model_aside(
    trained_models: dict[str, Model],
) -> None:
    lerp = trained_models["viseme-lerp"]
    assert isinstance(lerp, VisemeLerpModel)
    faulty = _FaultyModel(
        replace(lerp.manifest, name="broken"),
        lerp.poses,
        lerp.durations,
        lerp.leads_ms,
        lerp.kappas,
    )
    registry = _registry(lerp, faulty)
    Catalog.build(registry, ServerSettings())
    assert list(registry.models) == ["good"]
    (failure,) = registry.failure_report()
    assert failure["model"] == "broken" and failure["code"] == "model_invalid"
    assert "ZeroDivisionError: a fault inside the engine" in failure["message"]


def test_a_model_whose_rung_synthesizes_non_finite_frames_is_refused_by_the_probe(
    trained_models: dict[str, Model],
) -> None:
    """Issue 29, defect 7: κ = 1e300 (built in memory, past the load-time range checks) is
    finite, and its damped rungs' frames are NaN; the lerp rung and silence are not."""
    lerp = trained_models["viseme-lerp"]
    assert isinstance(lerp, VisemeLerpModel)
    manifest = replace(lerp.manifest, name="broken")
    absurd = VisemeLerpModel(
        manifest, lerp.poses, lerp.durations, lerp.leads_ms, np.full_like(lerp.kappas, 1e300)
    )
    spans = [("AA", 0.0, 0.2), ("M", 0.2, 0.3)]
    assert np.isfinite(absurd.synthesize(spans, mode="lerp").frames).all()
    assert not np.isfinite(absurd.synthesize(spans, mode="damped", lead_ms=0).frames).all()
    registry = _registry(lerp, absurd)
    Catalog.build(registry, ServerSettings())
    assert list(registry.models) == ["good"]
    error = registry.failures["broken"].error
    assert (error.code, error.where) == ("model_invalid", "/m/broken: probe on rung damped_lead")
    assert "NaN or infinite values from the calibration utterance" in error.message
