"""Model directories and catalogs for the server tests, from the shared trained models."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import pytest

from lipstream.config import ServerSettings
from lipstream.models import ModelRegistry
from lipstream.server.catalog import Catalog

if TYPE_CHECKING:
    from lipstream.engines.base import Model


@pytest.fixture(scope="session")
def lerp_dir(trained_models: dict[str, Model], tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Only the viseme-lerp model: fast to load, for servers testing limits."""
    directory = tmp_path_factory.mktemp("server-models-lerp")
    trained_models["viseme-lerp"].save(directory / "viseme-lerp")
    return directory


@pytest.fixture(scope="session")
def catalog(all_models_dir: Path) -> Catalog:
    """A catalog of every model with default settings."""
    return Catalog.build(ModelRegistry.load(all_models_dir), ServerSettings())
