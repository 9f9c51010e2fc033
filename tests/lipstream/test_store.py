import json
import zipfile
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import lipstream
from lipstream.errors import ModelStoreError
from lipstream.store import (
    ARRAYS_NAME,
    MANIFEST_NAME,
    MAX_MANIFEST_BYTES,
    MAX_MANIFEST_DEPTH,
    SCHEMA_VERSION,
    ModelManifest,
    load_arrays,
    read_manifest,
    require_arrays,
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
    arrays: dict[str, np.ndarray] = {
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
    sizes = {name: array.nbytes for name, array in arrays.items()}
    stored = replace(_manifest(), arrays_file_bytes=(tmp_path / ARRAYS_NAME).stat().st_size)
    assert read_manifest(tmp_path) == replace(stored, array_data_bytes=sizes)


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


def _write_manifest(directory: Path, text: str) -> None:
    directory.mkdir(parents=True, exist_ok=True)
    (directory / MANIFEST_NAME).write_text(text, encoding="utf-8")


def _fields() -> dict[str, object]:
    fields: dict[str, object] = json.loads(_manifest().to_json())
    return fields


@pytest.mark.parametrize(
    ("field", "value", "named"),
    [
        ("fps", "sixty", "fps"),
        ("fps", -0.5, "fps"),
        ("fps", 0, "fps"),
        ("fps", 1001, "fps"),
        ("fps", False, "fps"),
        ("engine", ["viseme-lerp"], "engine"),
        ("name", {"first": "demo"}, "name"),
        ("name", "x" * 129, "name"),
        ("channels", "jawOpen", "channels"),
        ("channels", ["jawOpen", 7], "channels[1]"),
        ("channels", ["jawOpen", "jawOpen"], "channels"),
        ("channels", [], "channels"),
        ("phoneme_set", [None], "phoneme_set[0]"),
        ("hyperparameters", [1, 2], "hyperparameters"),
        ("metrics", "fast", "metrics"),
        ("extra", 3, "extra"),
        ("corpus_digest", 12, "corpus_digest"),
        ("lipstream_version", None, "lipstream_version"),
    ],
)
def test_a_field_of_the_wrong_type_is_model_invalid_naming_it(
    tmp_path: Path, field: str, value: object, named: str
) -> None:
    data = _fields()
    data[field] = value
    _write_manifest(tmp_path, json.dumps(data))
    with pytest.raises(ModelStoreError) as caught:
        read_manifest(tmp_path)
    assert caught.value.code == "model_invalid"
    assert caught.value.where == f"{tmp_path / MANIFEST_NAME}: {named}"


@pytest.mark.parametrize("field", ["engine", "name", "channels", "fps", "phoneme_set"])
def test_a_missing_field_is_named(tmp_path: Path, field: str) -> None:
    data = _fields()
    del data[field]
    _write_manifest(tmp_path, json.dumps(data))
    with pytest.raises(ModelStoreError, match="is missing") as caught:
        read_manifest(tmp_path)
    assert caught.value.where == f"{tmp_path / MANIFEST_NAME}: {field}"


@pytest.mark.parametrize("depth", [33, 1000, 10_000, 100_000])
def test_deep_nesting_is_refused_without_recursing(tmp_path: Path, depth: int) -> None:
    text = json.dumps({**_fields(), "metrics": "@"}).replace('"@"', "[" * depth + "]" * depth)
    _write_manifest(tmp_path, text)
    with pytest.raises(ModelStoreError, match="nest") as caught:
        read_manifest(tmp_path)
    assert caught.value.code == "model_invalid"
    assert caught.value.where == str(tmp_path / MANIFEST_NAME)


def test_nesting_up_to_the_limit_is_read(tmp_path: Path) -> None:
    # The manifest is level 1 and ``metrics`` level 2, so its lists may reach level 32.
    def manifest(lists: int) -> str:
        return json.dumps({**_fields(), "metrics": {"deep": "@"}}).replace(
            '"@"', "[" * lists + "]" * lists
        )

    _write_manifest(tmp_path, manifest(MAX_MANIFEST_DEPTH - 2))
    nested = read_manifest(tmp_path).metrics["deep"]
    for _ in range(MAX_MANIFEST_DEPTH - 3):
        (nested,) = nested
    assert nested == []
    _write_manifest(tmp_path, manifest(MAX_MANIFEST_DEPTH - 1))
    with pytest.raises(ModelStoreError, match=f"more than {MAX_MANIFEST_DEPTH} deep"):
        read_manifest(tmp_path)


@pytest.mark.parametrize("constant", ["NaN", "Infinity", "-Infinity"])
def test_non_finite_constants_are_not_json(tmp_path: Path, constant: str) -> None:
    text = json.dumps(_fields()).replace('"fps": 120.0', f'"fps": {constant}')
    assert constant in text
    _write_manifest(tmp_path, text)
    with pytest.raises(ModelStoreError, match=f"{constant} is not a JSON number"):
        read_manifest(tmp_path)


def test_an_oversized_manifest_is_refused_before_parsing(tmp_path: Path) -> None:
    data = {**_fields(), "metrics": {"padding": "x" * MAX_MANIFEST_BYTES}}
    _write_manifest(tmp_path, json.dumps(data))
    with pytest.raises(ModelStoreError, match=f"larger than {MAX_MANIFEST_BYTES} bytes"):
        read_manifest(tmp_path)


def test_a_boolean_schema_version_is_not_version_one(tmp_path: Path) -> None:
    _write_manifest(tmp_path, json.dumps({**_fields(), "schema_version": True}))
    with pytest.raises(ModelStoreError) as caught:
        read_manifest(tmp_path)
    assert caught.value.code == "model_schema_version"


def test_a_missing_array_is_named(tmp_path: Path) -> None:
    with pytest.raises(ModelStoreError, match="is missing") as caught:
        require_arrays({"a": np.ones(2)}, ["a", "b", "c"], tmp_path)
    assert caught.value.where == f"{tmp_path / ARRAYS_NAME}: b"
    assert "['b', 'c']" in caught.value.message


def test_an_array_header_claiming_more_data_than_the_file_holds(tmp_path: Path) -> None:
    save_model_dir(tmp_path, _manifest(), {"a": np.ones(10)})
    raw = (tmp_path / ARRAYS_NAME).read_bytes()
    assert b"'shape': (10,), }" in raw
    (tmp_path / ARRAYS_NAME).write_bytes(raw.replace(b"'shape': (10,), }", b"'shape': (9999,)}"))
    with pytest.raises(ModelStoreError, match="more than its member stores"):
        load_arrays(tmp_path)


def test_missing_model_path_says_no_such_directory(tmp_path: Path) -> None:
    missing = tmp_path / "models" / "viseme-lerp"
    with pytest.raises(ModelStoreError, match="no such directory") as raised:
        lipstream.load_model(missing)
    assert raised.value.where == str(missing)
    (tmp_path / "file").write_text("x")
    with pytest.raises(ModelStoreError, match="not a directory"):
        read_manifest(tmp_path / "file")
