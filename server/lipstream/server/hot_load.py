"""Serving characters trained while the server runs, without a restart.

Sketch: a character directory (``<name>/<engine>/`` model directories, from a recording
job) is loaded into a registry of its own, each model keyed ``<name>/<engine>`` so it never
collides with the models loaded at start. A ``Catalog`` is built for it exactly as at
start-up (warm-up, calibration, probes and their bounds, presets), on the watcher's
thread, and then merged into the server's: every table is replaced by a new dict holding
the old entries and the new (never changed in place), facts before models, so the
sessions on the event loop and in the pools, which read the tables without locks, see a
model only once its facts are there. A character whose name the server already serves, or
none of whose models pass, is not served; the error says why.
"""

from __future__ import annotations

import logging
from pathlib import Path

from ..engines import load_model
from ..errors import LipstreamError, ModelStoreError
from ..models import ModelRegistry, model_dirs, model_failure
from .catalog import Catalog

logger = logging.getLogger("lipstream.server")


def load_character(served: Catalog, directory: Path) -> LipstreamError | None:
    """Serve the character in ``directory`` from now on beside ``served``'s models (a
    server's catalog); the error when it cannot be."""
    name = directory.name
    if name in served.registry.characters():
        return LipstreamError(
            f"a character {name!r} is served already", where=name, code="name_taken"
        )
    registry = ModelRegistry(root=directory)
    try:
        for model_dir in model_dirs(directory):
            key = f"{name}/{model_dir.name}"
            try:
                registry.models[key] = load_model(model_dir)
                registry.directories[key] = model_dir
            except LipstreamError as error:
                registry.failures[key] = model_failure(model_dir, error)
        catalog = Catalog.build(registry, served.settings)
    except LipstreamError as error:
        return error
    except Exception as error:  # a fault in one character must not stop the server
        logger.exception("loading the character %s failed", directory)
        return ModelStoreError(f"could not be loaded: {type(error).__name__}: {error}", where=name)
    _merge(served, catalog)
    logger.info(
        "serving the new character %s (%s)", name, ", ".join(sorted(registry.characters()[name]))
    )
    return None


def _merge(catalog: Catalog, new: Catalog) -> None:
    registry = catalog.registry
    catalog.facts = {**catalog.facts, **new.facts}
    catalog.presets = {**new.presets, **catalog.presets}
    registry.directories = {**registry.directories, **new.registry.directories}
    registry.failures = {**registry.failures, **new.registry.failures}
    registry.models = {**registry.models, **new.registry.models}
