"""espeak-ng's own speech of demo sentences, with its word and phoneme events: the truth
the word-timing front ends are measured against; and a duration model trained on other
sentences spoken the same way."""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

from lipstream.demo.sentences import load_sentences
from lipstream.frontends.word_durations import WordDurationModel
from lipstream.speech.spoken_words import SpokenUtterance, speak_words

if TYPE_CHECKING:
    from lipstream.corpus import Corpus

TRAINING_SENTENCES = 120
HELDOUT_SENTENCES = 30


@pytest.fixture(scope="session")
def espeak_spoken() -> tuple[list[SpokenUtterance], list[SpokenUtterance]]:
    """(training, held-out) utterances: different sentences, spoken by espeak-ng."""
    if shutil.which("espeak-ng") is None:
        pytest.skip("espeak-ng missing")
    sentences = load_sentences()
    training = speak_words(sentences[:TRAINING_SENTENCES])
    heldout = speak_words(sentences[-HELDOUT_SENTENCES:])
    return training, heldout


@pytest.fixture(scope="session")
def espeak_durations(
    espeak_spoken: tuple[list[SpokenUtterance], list[SpokenUtterance]],
) -> WordDurationModel:
    training, _ = espeak_spoken
    return WordDurationModel().fit(utterance.spans for utterance in training)


@pytest.fixture(scope="session")
def lerp_model_dir(small_demo_corpus: Corpus, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A viseme-lerp model trained by ``train_engine``, which saves its duration model."""
    from lipstream.training import train_engine

    directory = tmp_path_factory.mktemp("frontends-lerp") / "viseme-lerp"
    train_engine(small_demo_corpus.split()[0], "viseme-lerp", directory)
    return directory
