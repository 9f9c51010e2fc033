"""Finding and holding the models a server process keeps resident."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from .engines import load_model
from .engines.base import Model
from .errors import LipstreamError, ModelStoreError
from .store import MANIFEST_NAME


def model_dirs(path: Path) -> list[Path]:
    """``path`` itself if it is a model directory, else its model subdirectories."""
    if (path / MANIFEST_NAME).is_file():
        return [path]
    if not path.is_dir():
        raise ModelStoreError("no such model directory", where=str(path))
    found = sorted(child for child in path.iterdir() if (child / MANIFEST_NAME).is_file())
    if not found:
        raise ModelStoreError("holds no model directories (none has model.json)", where=str(path))
    return found


@dataclass
class ModelRegistry:
    """Resident models by name (their directory name), with lookup by character and engine."""

    models: dict[str, Model] = field(default_factory=dict)

    @classmethod
    def load(cls, path: Path) -> ModelRegistry:
        return cls({directory.name: load_model(directory) for directory in model_dirs(path)})

    def characters(self) -> dict[str, list[str]]:
        """Character name -> engines that serve it."""
        table: dict[str, list[str]] = {}
        for model in self.models.values():
            table.setdefault(model.name, []).append(model.manifest.engine)
        return {name: sorted(engines) for name, engines in sorted(table.items())}

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
