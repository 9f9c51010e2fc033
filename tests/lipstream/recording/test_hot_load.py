"""The model watcher and the hot load, as two workers see them: two watchers over one
models directory, each feeding its own catalog (its own registry), both serving a character
published after they started."""

from __future__ import annotations

import dataclasses
import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from lipstream.config import ServerSettings
from lipstream.corpus import Corpus
from lipstream.models import ModelRegistry
from lipstream.recording.watcher import ModelWatcher, bump_generation
from lipstream.server.catalog import Catalog
from lipstream.server.hot_load import load_character
from lipstream.training import train_engine
from tests.lipstream.server.harness import fixed_calibration


@pytest.fixture(scope="module")
def demo_models(small_demo_corpus: Corpus, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """What a worker serves from start: the demo character's viseme-lerp model."""
    directory = tmp_path_factory.mktemp("served")
    train_engine(small_demo_corpus.split()[0], "viseme-lerp", directory / "viseme-lerp")
    return directory


@pytest.fixture(scope="module")
def new_character(small_demo_corpus: Corpus, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A character ``fresh`` (viseme-lerp), trained as a recording job would train it."""
    corpus = dataclasses.replace(small_demo_corpus.split()[0], name="fresh")
    directory = tmp_path_factory.mktemp("trained") / "fresh"
    train_engine(corpus, "viseme-lerp", directory / "viseme-lerp")
    return directory


def test_each_watcher_hands_over_each_new_character_once(tmp_path: Path) -> None:
    models = tmp_path / "models"
    seen: tuple[list[Path], list[Path]] = ([], [])
    first, second = (ModelWatcher(models, handed.extend) for handed in seen)
    assert first.check() == [] and second.check() == []  # no directory yet
    (models / "alice").mkdir(parents=True)
    bump_generation(models)
    assert first.check() == [models / "alice"] and second.check() == [models / "alice"]
    assert first.check() == [] and second.check() == []  # the generation did not change
    (models / "bob").mkdir()
    (models / ".partial").mkdir()
    assert first.check() == []  # published, but not announced yet
    bump_generation(models)
    assert first.check() == [models / "bob"] and second.check() == [models / "bob"]
    assert seen == ([models / "alice", models / "bob"], [models / "alice", models / "bob"])


def test_two_workers_serve_a_character_published_while_they_run(
    demo_models: Path, new_character: Path, tmp_path: Path
) -> None:
    models = tmp_path / "models"
    models.mkdir()
    with fixed_calibration():
        workers = [
            Catalog.build(ModelRegistry.load(demo_models), ServerSettings()) for _ in range(2)
        ]
        watchers = [ModelWatcher(models, _loader(served)) for served in workers]
        for watcher in watchers:
            watcher.check()
        assert all("fresh" not in served.registry.characters() for served in workers)
        shutil.copytree(new_character, models / "fresh")
        bump_generation(models)
        for watcher in watchers:
            watcher.check()
    for served in workers:
        assert served.registry.characters() == {
            "demo": ["viseme-lerp"],
            "fresh": ["viseme-lerp"],
        }
        model = served.model("viseme-lerp", "fresh")
        assert served.ladder(model) and np.isfinite(served.rest_pose(model, None)).all()
        assert served.registry.directories["fresh/viseme-lerp"] == models / "fresh" / "viseme-lerp"
        assert served.model("viseme-lerp", "demo") is not model
    assert workers[0].model("viseme-lerp", "fresh") is not workers[1].model("viseme-lerp", "fresh")


def _loader(served: Catalog) -> Callable[[list[Path]], None]:
    def load(found: list[Path]) -> None:
        for directory in found:
            assert load_character(served, directory) is None

    return load


def test_a_character_that_cannot_be_served_is_refused_with_its_reason(
    demo_models: Path, new_character: Path, tmp_path: Path
) -> None:
    with fixed_calibration():
        served = Catalog.build(ModelRegistry.load(demo_models), ServerSettings())
        clash = tmp_path / "demo"
        shutil.copytree(new_character, clash)
        taken = load_character(served, clash)
        empty = tmp_path / "empty"
        empty.mkdir()
        nothing = load_character(served, empty)
    assert taken is not None and taken.code == "name_taken"
    assert nothing is not None and "no model directories" in nothing.message
    assert served.registry.characters() == {"demo": ["viseme-lerp"]}
