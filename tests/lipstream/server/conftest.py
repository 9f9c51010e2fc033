"""Model directories and catalogs for the server tests, from the shared trained models."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from lipstream.config import ServerSettings
from lipstream.models import ModelRegistry
from lipstream.server.catalog import Catalog
from tests.lipstream.server.browser import CHROMIUM, LAUNCH_ARGS
from tests.lipstream.server.harness import fixed_calibration


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
