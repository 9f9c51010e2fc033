"""Engine registry: names map to lazy import strings, so unused engines cost nothing."""

from __future__ import annotations

import importlib
from pathlib import Path

from ..errors import UnknownEngineError
from ..store import read_manifest
from .base import Engine, Model

ENGINES: dict[str, str] = {
    "viseme-lerp": "lipstream.engines.viseme_lerp:VisemeLerpEngine",
    "anime-graph": "lipstream.engines.anime_graph:AnimeGraphEngine",
    "dam": "lipstream.engines.dam:DamEngine",
    "cohen-massaro": "lipstream.engines.dam:CohenMassaroEngine",
    "hmm": "lipstream.engines.hmm:HmmEngine",
    "expressive-dp": "lipstream.engines.expressive_dp:ExpressiveDpEngine",
}


def engine_names() -> list[str]:
    return list(ENGINES)


def get_engine_class(name: str) -> type[Engine]:
    """Import and return the engine registered as ``name``."""
    try:
        target = ENGINES[name]
    except KeyError:
        raise UnknownEngineError(
            f"unknown engine {name!r}; available: {', '.join(ENGINES)}", where="engine"
        ) from None
    module_name, _, attribute = target.partition(":")
    engine_class: type[Engine] = getattr(importlib.import_module(module_name), attribute)
    return engine_class


def load_model(path: str | Path) -> Model:
    """Load any model directory, dispatching on the engine named in its manifest."""
    directory = Path(path).expanduser()
    manifest = read_manifest(directory)
    return get_engine_class(manifest.engine).model_class.load(directory)
