"""Finding and holding the models a server process keeps resident.

Sketch: ``ModelRegistry.load`` loads every model directory on its own, so one
that fails its load-time checks (``lipstream.model_checks``) is set aside as a
``ModelFailure`` (logged, and listed by ``/readyz`` and ``/v1/characters``)
while the others are served. Loading fails as a whole only when no model
loads, or at the first failure when ``strict``. The server may also ``drop``
a loaded model whose start-up probes fail.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .engines import load_model
from .engines.base import Model
from .errors import LipstreamError, ModelStoreError
from .store import MANIFEST_NAME, read_manifest

logger = logging.getLogger(__name__)


def model_dirs(path: Path) -> list[Path]:
    """``path`` itself if it is a model directory, else its model subdirectories."""
    if (path / MANIFEST_NAME).is_file():
        return [path]
    if not path.is_dir():
        raise ModelStoreError("no such directory", where=str(path))
    found = sorted(child for child in path.iterdir() if (child / MANIFEST_NAME).is_file())
    if not found:
        raise ModelStoreError("holds no model directories (none has model.json)", where=str(path))
    return found


@dataclass(frozen=True)
class ModelFailure:
    """A model directory that is not served: its name, the engine and character its manifest
    names (None when unreadable) and the error."""

    directory: Path
    error: LipstreamError
    engine: str | None = None
    character: str | None = None

    @property
    def name(self) -> str:
        return self.directory.name

    def to_json(self) -> dict[str, Any]:
        """What the HTTP routes report: paths relative to the models' parent directory, so
        the server's file system layout stays private."""
        where = self.error.where or ""
        root = str(self.directory.parent) + "/"
        return {
            "model": self.name,
            "engine": self.engine,
            "character": self.character,
            "code": self.error.code,
            "where": where[len(root) :] if where.startswith(root) else where,
            "message": self.error.message,
        }


def model_failure(directory: Path, error: LipstreamError) -> ModelFailure:
    """The failure of ``directory`` with what its manifest names (if it reads)."""
    try:
        manifest = read_manifest(directory)
    except LipstreamError:
        return ModelFailure(directory, error)
    return ModelFailure(directory, error, manifest.engine, manifest.name)


@dataclass
class ModelRegistry:
    """Resident models by name (their directory name), with lookup by character and engine;
    ``failures`` are the directories that are not served, by name."""

    models: dict[str, Model] = field(default_factory=dict)
    failures: dict[str, ModelFailure] = field(default_factory=dict)
    directories: dict[str, Path] = field(default_factory=dict)
    root: Path = Path(".")

    @classmethod
    def load(cls, path: Path, *, strict: bool = False) -> ModelRegistry:
        """Every model under ``path``; a model that fails to load is logged and recorded in
        ``failures``. Raises when none loads, or (``strict``) when any fails."""
        registry = cls(root=path)
        for directory in model_dirs(path):
            try:
                registry.models[directory.name] = load_model(directory)
                registry.directories[directory.name] = directory
            except LipstreamError as error:
                registry._fail(directory, error)
            except Exception as error:  # a model the checks missed still stays apart
                logger.exception("model %s: unexpected error while loading", directory)
                wrapped = ModelStoreError(
                    f"could not be loaded: {type(error).__name__}: {error}", where=str(directory)
                )
                registry._fail(directory, wrapped)
        registry.require_models(strict=strict)
        return registry

    def _fail(self, directory: Path, error: LipstreamError) -> None:
        logger.error("model %s is not served: %s", directory, error)
        self.failures[directory.name] = model_failure(directory, error)

    def require_models(self, *, strict: bool) -> None:
        """Raise the first failure when ``strict``, and an error when no model is left."""
        if strict and self.failures:
            raise next(iter(self.failures.values())).error
        if not self.models:
            listed = "; ".join(str(failure.error) for failure in self.failures.values())
            raise ModelStoreError(f"no model could be loaded ({listed})", where=str(self.root))

    def drop(self, name: str, error: LipstreamError) -> None:
        """Stop serving the model ``name``, recording ``error``."""
        model = self.models.pop(name)
        directory = self.directories.get(name, Path(name))
        logger.error("model %s is not served: %s", directory, error)
        self.failures[name] = ModelFailure(directory, error, model.manifest.engine, model.name)

    def characters(self) -> dict[str, list[str]]:
        """Character name -> engines that serve it."""
        table: dict[str, list[str]] = {}
        for model in self.models.values():
            table.setdefault(model.name, []).append(model.manifest.engine)
        return {name: sorted(engines) for name, engines in sorted(table.items())}

    def failure_report(self) -> list[dict[str, Any]]:
        """The failed models as ``ModelFailure.to_json``, by directory name."""
        return [self.failures[name].to_json() for name in sorted(self.failures)]

    def find(self, engine: str, character: str | None = None) -> Model:
        """The model of ``engine`` for ``character`` (any character when None)."""
        for model in self.models.values():
            if model.manifest.engine == engine and character in (None, model.name):
                return model
        raise LipstreamError(
            f"no model for engine {engine!r}"
            + (f" and character {character!r}" if character else ""),
            where="engine",
            code="unknown_model",
        )
