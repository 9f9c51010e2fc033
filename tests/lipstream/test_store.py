import json
import zipfile
from pathlib import Path

import numpy as np
import pytest

from lipstream.errors import ModelStoreError
from lipstream.store import (
    ARRAYS_NAME,
    MANIFEST_NAME,
    SCHEMA_VERSION,
    ModelManifest,
    load_arrays,
    read_manifest,
    save_model_dir,
)


def _manifest() -> ModelManifest:
    return ModelManifest(
        engine="viseme-lerp",
        name="demo",
        channels=["jawOpen", "mouthClose"],
        fps=120.0,
        phoneme_set=["AA", "sil"],
        hyperparameters={"scheme": "oculus15"},
        corpus_digest="abc",
        metrics={"train_seconds": 1.5},
    )


def test_round_trip_memory_maps_every_array(tmp_path: Path) -> None:
    arrays = {
        "poses": np.arange(12, dtype=np.float32).reshape(3, 4),
        "index": np.array([5, -1, 7], dtype=np.int64),
        "fortran": np.asfortranarray(np.arange(6, dtype=np.float64).reshape(2, 3)),
        "empty": np.zeros((0, 3), dtype=np.float32),
    }
    save_model_dir(tmp_path, _manifest(), arrays)
    loaded = load_arrays(tmp_path)
    assert set(loaded) == set(arrays)
    for name, original in arrays.items():
        np.testing.assert_array_equal(loaded[name], original)
        assert loaded[name].dtype == original.dtype
    assert isinstance(loaded["poses"], np.memmap)
    assert not loaded["poses"].flags.writeable
    assert read_manifest(tmp_path) == _manifest()


def test_manifest_has_no_pickle_and_arrays_are_uncompressed(tmp_path: Path) -> None:
    save_model_dir(tmp_path, _manifest(), {"a": np.ones(4)})
    data = json.loads((tmp_path / MANIFEST_NAME).read_text())
    assert data["schema_version"] == SCHEMA_VERSION and data["engine"] == "viseme-lerp"
    with zipfile.ZipFile(tmp_path / ARRAYS_NAME) as archive:
        assert all(info.compress_type == zipfile.ZIP_STORED for info in archive.infolist())


def test_wrong_schema_version_is_a_clear_error(tmp_path: Path) -> None:
    save_model_dir(tmp_path, _manifest(), {"a": np.ones(4)})
    data = json.loads((tmp_path / MANIFEST_NAME).read_text())
    data["schema_version"] = 99
    (tmp_path / MANIFEST_NAME).write_text(json.dumps(data))
    with pytest.raises(ModelStoreError) as caught:
        read_manifest(tmp_path)
    assert caught.value.code == "model_schema_version"
    assert "99" in str(caught.value) and MANIFEST_NAME in str(caught.value)


@pytest.mark.parametrize("content", ["{not json", "[1, 2]", json.dumps({"schema_version": 1})])
def test_broken_manifest_is_a_clear_error(tmp_path: Path, content: str) -> None:
    (tmp_path / MANIFEST_NAME).write_text(content)
    with pytest.raises(ModelStoreError) as caught:
        read_manifest(tmp_path)
    assert MANIFEST_NAME in str(caught.value)


def test_compressed_and_object_arrays_are_refused(tmp_path: Path) -> None:
    np.savez_compressed(tmp_path / ARRAYS_NAME, a=np.ones(100))
    with pytest.raises(ModelStoreError, match="compressed"):
        load_arrays(tmp_path)
    np.savez(tmp_path / ARRAYS_NAME, a=np.array([{"x": 1}], dtype=object))
    with pytest.raises(ModelStoreError, match="Python objects"):
        load_arrays(tmp_path)


def test_truncated_archive_is_a_clear_error(tmp_path: Path) -> None:
    save_model_dir(tmp_path, _manifest(), {"a": np.ones(1000)})
    raw = (tmp_path / ARRAYS_NAME).read_bytes()
    (tmp_path / ARRAYS_NAME).write_bytes(raw[: len(raw) // 2])
    with pytest.raises(ModelStoreError, match=ARRAYS_NAME):
        load_arrays(tmp_path)


def test_not_a_model_directory(tmp_path: Path) -> None:
    with pytest.raises(ModelStoreError, match="no model.json"):
        read_manifest(tmp_path)
