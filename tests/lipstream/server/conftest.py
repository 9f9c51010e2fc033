"""Model directories and catalogs for the server tests, from the shared trained models."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from lipstream.config import ServerSettings
from lipstream.engines.base import Model, Rung
from lipstream.models import ModelRegistry
from lipstream.server.calibration import ComputeCost
from lipstream.server.catalog import Catalog

# What every rung costs under ``fixed_calibration``: rung choices then follow from the
# models' lookahead alone, not from how fast a (loaded) machine ran the calibration.
FIXED_COMPUTE_MS = 1.0


def _fixed_cost(model: Model, rung: Rung) -> ComputeCost:
    return ComputeCost(FIXED_COMPUTE_MS, FIXED_COMPUTE_MS, per_frame_ms=0.001)


@contextmanager
def fixed_calibration() -> Iterator[None]:
    """Catalogs built meanwhile (a server's too) measure every rung at ``FIXED_COMPUTE_MS``;
    the warm-up still runs, since it compiles the engines' kernels."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr("lipstream.server.catalog.measure", _fixed_cost)
        yield


@pytest.fixture(scope="session")
def fixed_cost_catalog(all_models_dir: Path) -> Catalog:
    """A catalog of every model with default settings, calibrated by ``fixed_calibration``."""
    with fixed_calibration():
        return Catalog.build(ModelRegistry.load(all_models_dir), ServerSettings())


@pytest.fixture(scope="session")
def catalog(all_models_dir: Path) -> Catalog:
    """A catalog of every model with default settings."""
    return Catalog.build(ModelRegistry.load(all_models_dir), ServerSettings())
