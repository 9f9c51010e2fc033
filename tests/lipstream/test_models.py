"""The model registry: one bad model directory is set aside, the others load."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest

from lipstream.engines.viseme_lerp import VisemeLerpEngine, VisemeLerpModel
from lipstream.errors import LipstreamError, ModelStoreError
from lipstream.models import ModelRegistry
from lipstream.store import ARRAYS_NAME, MANIFEST_NAME, save_model_dir
from tests.lipstream.engines.anime_graph.anime_synthetic import make_corpus


@pytest.fixture(scope="module")
def lerp() -> VisemeLerpModel:
    return VisemeLerpEngine().fit(make_corpus(seed=3, n_utterances=4, with_audio=False))


def _nan_copy(model: VisemeLerpModel, directory: Path) -> None:
    save_model_dir(directory, model.manifest, {"poses": model.poses * np.nan})


def test_a_bad_model_is_set_aside_and_the_good_one_serves(
    lerp: VisemeLerpModel, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    lerp.save(tmp_path / "good")
    _nan_copy(lerp, tmp_path / "nan")
    (tmp_path / "unreadable").mkdir()
    (tmp_path / "unreadable" / MANIFEST_NAME).write_text("{", encoding="utf-8")
    with caplog.at_level(logging.ERROR, logger="lipstream.models"):
        registry = ModelRegistry.load(tmp_path)
    assert list(registry.models) == ["good"]
    assert registry.characters() == {lerp.name: ["viseme-lerp"]}
    assert registry.failure_report() == [
        {
            "model": "nan",
            "engine": "viseme-lerp",
            "character": lerp.name,
            "code": "model_invalid",
            "where": f"nan/{ARRAYS_NAME}: poses",
            "message": f"holds {lerp.poses.size} NaN or infinite values (first at (0, 0))",
        },
        {
            "model": "unreadable",
            "engine": None,
            "character": None,
            "code": "model_invalid",
            "where": f"unreadable/{MANIFEST_NAME}",
            "message": registry.failures["unreadable"].error.message,
        },
    ]
    assert registry.failures["unreadable"].error.message.startswith("model.json is not valid JSON")
    logged = [record.getMessage() for record in caplog.records]
    assert logged == [
        f"model {tmp_path / name} is not served: {registry.failures[name].error}"
        for name in ("nan", "unreadable")
    ]


def test_no_loadable_model_is_an_error_listing_the_failures(
    lerp: VisemeLerpModel, tmp_path: Path
) -> None:
    _nan_copy(lerp, tmp_path / "a")
    _nan_copy(lerp, tmp_path / "b")
    with pytest.raises(ModelStoreError, match="no model could be loaded") as caught:
        ModelRegistry.load(tmp_path)
    assert caught.value.where == str(tmp_path)
    assert str(tmp_path / "a" / ARRAYS_NAME) in caught.value.message
    assert str(tmp_path / "b" / ARRAYS_NAME) in caught.value.message


def test_strict_loading_raises_the_first_failure(lerp: VisemeLerpModel, tmp_path: Path) -> None:
    lerp.save(tmp_path / "good")
    _nan_copy(lerp, tmp_path / "bad")
    with pytest.raises(ModelStoreError) as caught:
        ModelRegistry.load(tmp_path, strict=True)
    assert caught.value.where == f"{tmp_path / 'bad' / ARRAYS_NAME}: poses"


def test_an_unexpected_exception_sets_only_that_model_aside(
    lerp: VisemeLerpModel, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    lerp.save(tmp_path / "good")
    lerp.save(tmp_path / "odd")
    real = VisemeLerpModel.from_arrays.__func__  # type: ignore[attr-defined]  # the classmethod's function

    def from_arrays(cls: type, manifest: object, arrays: object, path: Path) -> object:
        if path.name == "odd":
            raise RuntimeError("a bug the checks missed")
        return real(cls, manifest, arrays, path)

    monkeypatch.setattr(VisemeLerpModel, "from_arrays", classmethod(from_arrays))
    registry = ModelRegistry.load(tmp_path)
    assert list(registry.models) == ["good"]
    error = registry.failures["odd"].error
    assert (error.code, error.where) == ("model_invalid", str(tmp_path / "odd"))
    assert error.message == "could not be loaded: RuntimeError: a bug the checks missed"


def test_dropping_a_model_moves_it_to_the_failures(lerp: VisemeLerpModel, tmp_path: Path) -> None:
    lerp.save(tmp_path / "a")
    lerp.save(tmp_path / "b")
    registry = ModelRegistry.load(tmp_path)
    registry.drop("a", LipstreamError("silence is not finite", where="probe", code="model_invalid"))
    assert list(registry.models) == ["b"]
    assert registry.failure_report()[0]["model"] == "a"
    assert registry.failure_report()[0]["engine"] == "viseme-lerp"
    registry.require_models(strict=False)
    with pytest.raises(LipstreamError, match="silence is not finite"):
        registry.require_models(strict=True)
    registry.drop("b", LipstreamError("also bad", code="model_invalid"))
    with pytest.raises(ModelStoreError, match="no model could be loaded"):
        registry.require_models(strict=False)
