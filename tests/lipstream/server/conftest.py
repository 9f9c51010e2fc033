"""Model directories and catalogs for the server tests, from the shared trained models."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

from lipstream.config import ServerSettings
from lipstream.engines.base import Model
from lipstream.engines.expressive_dp import ExpressiveDpModel
from lipstream.frontends.word_durations import WordDurationModel
from lipstream.models import ModelRegistry
from lipstream.server.catalog import Catalog
from tests.lipstream.server.browser import CHROMIUM, LAUNCH_ARGS
from tests.lipstream.server.harness import fixed_calibration

if TYPE_CHECKING:
    from lipstream.corpus import Corpus


@pytest.fixture(scope="session")
def fixed_cost_catalog(all_models_dir: Path) -> Catalog:
    """A catalog of every model with default settings, calibrated by ``fixed_calibration``."""
    with fixed_calibration():
        return Catalog.build(ModelRegistry.load(all_models_dir), ServerSettings())


@pytest.fixture(scope="session")
def catalog(all_models_dir: Path) -> Catalog:
    """A catalog of every model with default settings."""
    return Catalog.build(ModelRegistry.load(all_models_dir), ServerSettings())


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    """Debian's chromium through Playwright, one per test module."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as playwright:
        chromium = playwright.chromium.launch(executable_path=str(CHROMIUM), args=LAUNCH_ARGS)
        yield chromium
        chromium.close()


@pytest.fixture(scope="session")
def words_models(small_demo_corpus: Corpus, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A viseme-lerp model trained by ``train_engine`` (its duration model beside it), quick
    to train and serve, for the word-timing requests."""
    from lipstream.training import train_engine

    directory = tmp_path_factory.mktemp("words-models")
    train_engine(small_demo_corpus.split()[0], "viseme-lerp", directory / "viseme-lerp")
    return directory


@pytest.fixture(scope="session")
def expressive_dp_model(trained_models: dict[str, Model]) -> ExpressiveDpModel:
    found = trained_models["expressive-dp"]
    assert isinstance(found, ExpressiveDpModel)
    return found


@pytest.fixture(scope="module")
def expressive_dp_dir(
    expressive_dp_model: ExpressiveDpModel,
    word_durations: WordDurationModel,
    tmp_path_factory: pytest.TempPathFactory,
) -> Path:
    """A models directory of its own per test module (its contamination file is the
    module's): the expressive-dp model with its word-duration model."""
    directory = tmp_path_factory.mktemp("expressive-dp-served")
    expressive_dp_model.save(directory / "expressive-dp")
    word_durations.save(directory / "expressive-dp")
    return directory
