"""Shared fixtures: a small demo corpus made by the real generator, and models trained on it."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import pytest

if TYPE_CHECKING:
    from lipstream.corpus import Corpus
    from lipstream.engines.base import Model
    from lipstream.frontends.word_durations import WordDurationModel

SMALL_DEMO_SENTENCES = 24


def pytest_configure(config: pytest.Config) -> None:
    from lipstream.numerics.direct_call import check_types

    check_types(True)  # a kernel called with other argument types than it was bound to fails


@pytest.fixture(scope="session")
def small_demo_corpus() -> Corpus:
    from lipstream.demo.generate import generate_demo_corpus

    return generate_demo_corpus(n_sentences=SMALL_DEMO_SENTENCES)


@pytest.fixture(scope="session")
def trained_models(small_demo_corpus: Corpus) -> dict[str, Model]:
    from lipstream.engines import engine_names
    from lipstream.training import train_engine

    train, _ = small_demo_corpus.split()
    return {name: train_engine(train, name) for name in engine_names()}


@pytest.fixture(scope="session")
def word_durations(small_demo_corpus: Corpus) -> WordDurationModel:
    """The duration model ``train_engine`` saves beside each model of the small corpus."""
    from lipstream.frontends.word_durations import WordDurationModel

    train, _ = small_demo_corpus.split()
    return WordDurationModel().fit(utterance.phones for utterance in train.utterances)


@pytest.fixture(scope="session")
def all_models_dir(
    trained_models: dict[str, Model],
    word_durations: WordDurationModel,
    tmp_path_factory: pytest.TempPathFactory,
) -> Path:
    """Every registered engine's model of the demo character."""
    directory = tmp_path_factory.mktemp("models-all")
    for name, model in trained_models.items():
        model.save(directory / name)
        word_durations.save(directory / name)
    return directory


@pytest.fixture(scope="session")
def lerp_dir(
    trained_models: dict[str, Model],
    word_durations: WordDurationModel,
    tmp_path_factory: pytest.TempPathFactory,
) -> Path:
    """Only the viseme-lerp model: fast to load, for servers testing limits."""
    directory = tmp_path_factory.mktemp("server-models-lerp")
    trained_models["viseme-lerp"].save(directory / "viseme-lerp")
    word_durations.save(directory / "viseme-lerp")
    return directory
