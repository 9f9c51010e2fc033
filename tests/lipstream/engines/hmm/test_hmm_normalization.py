"""Speaker normalization in the ``hmm`` model: stored as JSON and arrays, what a model saved
before it does, and the phoneme-driven frames it leaves alone."""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np
import pytest

from lipstream.corpus import Corpus, Utterance
from lipstream.engines import load_model
from lipstream.engines.hmm import HmmEngine, HmmModel
from lipstream.errors import LipstreamError
from lipstream.store import ARRAYS_NAME, MANIFEST_NAME, save_model_dir


@pytest.fixture(scope="module")
def models(small_demo_corpus: Corpus) -> dict[bool, HmmModel]:
    train = small_demo_corpus.split()[0]
    return {
        flag: HmmEngine(n_states=12, n_iter=4, speaker_normalization=flag).fit(train)
        for flag in (True, False)
    }


@pytest.fixture(scope="module")
def line(small_demo_corpus: Corpus) -> Utterance:
    return small_demo_corpus.split()[1].utterances[0]


def test_normalization_leaves_phoneme_driven_frames_bit_for_bit(
    models: dict[bool, HmmModel], small_demo_corpus: Corpus
) -> None:
    for utterance in small_demo_corpus.split()[1].utterances:
        with_it = models[True].synthesize(utterance.phones, 60.0, None, utterance.emotion)
        without = models[False].synthesize(utterance.phones, 60.0, None, utterance.emotion)
        np.testing.assert_array_equal(with_it.frames, without.frames)


def test_the_prior_is_stored_as_json_and_plain_arrays(
    models: dict[bool, HmmModel], tmp_path: Path
) -> None:
    models[True].save(tmp_path)
    manifest = json.loads((tmp_path / MANIFEST_NAME).read_text())
    assert set(manifest["extra"]["normalization"]) == {
        "prior_frames",
        "gate_nats",
        "silence_energy",
        "energy_column",
    }
    with zipfile.ZipFile(tmp_path / ARRAYS_NAME) as archive:
        names = set(archive.namelist())
    assert {"vocal_prior_mean.npy", "vocal_prior_variance.npy"} <= names
    with np.load(tmp_path / ARRAYS_NAME, allow_pickle=False) as arrays:  # no object arrays
        assert arrays["vocal_prior_mean"].dtype == np.float64
    loaded = load_model(tmp_path)
    stored = models[True].speaker_prior
    assert isinstance(loaded, HmmModel) and loaded.speaker_prior is not None and stored
    np.testing.assert_array_equal(loaded.speaker_prior.mean, stored.mean)


def test_a_model_saved_before_normalization_hears_raw_features_as_it_was_trained(
    models: dict[bool, HmmModel], line: Utterance, tmp_path: Path
) -> None:
    models[False].save(tmp_path)
    manifest = json.loads((tmp_path / MANIFEST_NAME).read_text())
    assert manifest["extra"]["normalization"] is None
    del manifest["extra"]["normalization"]  # as a model written before the field existed
    del manifest["hyperparameters"]["speaker_normalization"]
    del manifest["hyperparameters"]["prior_frames"]
    (tmp_path / MANIFEST_NAME).write_text(json.dumps(manifest))
    old = load_model(tmp_path)
    assert isinstance(old, HmmModel) and old.speaker_prior is None
    audio = line.audio
    np.testing.assert_array_equal(
        old.synthesize([], 60.0, audio).frames, models[False].synthesize([], 60.0, audio).frames
    )


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("energy_column", 28, "extra.normalization.energy_column"),
        ("prior_frames", -1.0, "extra.normalization.prior_frames"),
        ("prior_frames", 0.0, "extra.normalization.prior_frames"),
        ("gate_nats", "wide", "extra.normalization.gate_nats"),
    ],
)
def test_a_bad_normalization_field_is_a_coded_error_naming_it(
    models: dict[bool, HmmModel], tmp_path: Path, field: str, value: object, message: str
) -> None:
    models[True].save(tmp_path)
    manifest = json.loads((tmp_path / MANIFEST_NAME).read_text())
    manifest["extra"]["normalization"][field] = value
    (tmp_path / MANIFEST_NAME).write_text(json.dumps(manifest))
    with pytest.raises(LipstreamError, match=message.replace(".", r"\.")) as caught:
        load_model(tmp_path)
    assert caught.value.code == "model_invalid"


def test_a_missing_prior_array_is_a_coded_error(
    models: dict[bool, HmmModel], tmp_path: Path
) -> None:
    model = models[True]
    arrays = model.arrays()
    del arrays["vocal_prior_variance"]
    save_model_dir(tmp_path, model.manifest, arrays)
    with pytest.raises(LipstreamError, match="vocal_prior_variance") as caught:
        load_model(tmp_path)
    assert caught.value.code == "model_invalid"
