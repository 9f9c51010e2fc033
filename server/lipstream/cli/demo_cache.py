"""The demo character ``lipstream serve`` falls back on: kept when its cached models serve
every registered engine and word timings, else built (again) before serving."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..config import Settings
from ..errors import LipstreamError

if TYPE_CHECKING:
    from pathlib import Path

    from ..models import ModelRegistry
    from ..status import Report


def demo_ready(
    settings: Settings, report: Report, *, build: bool, check: bool
) -> ModelRegistry | None:
    """Build the demo character when there are no models, or when its cached models cannot
    serve every engine (``cached_demo``); the cached models when the check loaded them
    (so the server does not load them twice)."""
    from ..status import phase
    from ..training import build_demo

    models = settings.demo_models_dir
    if build:
        report(f"no models in {models}: building the demo character first")
    elif check:
        with phase(f"checking the demo character in {models}", report):
            cached = cached_demo(models)
        if cached is not None:
            return cached
        report(
            f"the demo character in {models} lacks an engine or was built by an older "
            "lipstream: building it again"
        )
    else:
        return None
    build_demo(settings.demo_dir, report=report)
    return None


def _stale_demo(models: Path) -> bool:
    """Whether the cached demo character cannot serve every registered engine (a model
    that no longer loads, or an engine added since it was built) or word timings (a model
    without its duration model, built before they were)."""
    return cached_demo(models) is None


def cached_demo(models: Path) -> ModelRegistry | None:
    """The cached demo character, loaded, when it serves every registered engine."""
    from ..engines import engine_names
    from ..frontends.word_durations import has_word_durations
    from ..models import ModelRegistry, model_dirs

    try:
        registry = ModelRegistry.load(models)
        directories = model_dirs(models)
    except LipstreamError:
        return None
    served = {model.manifest.engine for model in registry.models.values()}
    if registry.failures or not set(engine_names()) <= served:
        return None
    if not all(has_word_durations(directory) for directory in directories):
        return None
    return registry
