"""The model store: one directory per trained model, shared by training and serving.

Layout of a model directory::

    model.json     manifest: schema version, engine, channels, fps, phoneme set,
                   hyperparameters, training-corpus digest, training metrics
    arrays.npz     uncompressed arrays

The ``.npz`` members are stored uncompressed, so each one is memory-mapped in
place (``mmap_mode="r"`` semantics): worker processes that load the same model
share its pages. No pickle is ever written or read.
"""

from __future__ import annotations

import json
import zipfile
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .errors import ModelStoreError

SCHEMA_VERSION = 1
MANIFEST_NAME = "model.json"
ARRAYS_NAME = "arrays.npz"
_LOCAL_HEADER_SIZE = 30


@dataclass
class ModelManifest:
    """What ``model.json`` holds."""

    engine: str
    name: str
    channels: list[str]
    fps: float
    phoneme_set: list[str]
    hyperparameters: dict[str, Any] = field(default_factory=dict)
    corpus_digest: str = ""
    metrics: dict[str, Any] = field(default_factory=dict)
    extra: dict[str, Any] = field(default_factory=dict)
    schema_version: int = SCHEMA_VERSION
    lipstream_version: str = ""

    def to_json(self) -> str:
        return json.dumps(asdict(self), indent=2, sort_keys=True, allow_nan=False)

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any], where: str) -> ModelManifest:
        version = data.get("schema_version")
        if version != SCHEMA_VERSION:
            raise ModelStoreError(
                f"schema version {version!r} is not supported (this lipstream reads "
                f"version {SCHEMA_VERSION}); retrain the model with `lipstream train`",
                where=where,
                code="model_schema_version",
            )
        known = set(cls.__dataclass_fields__)
        unknown = sorted(set(data) - known)
        if unknown:
            raise ModelStoreError(f"unknown manifest keys {unknown}", where=where)
        try:
            return cls(**data)
        except TypeError as exc:
            raise ModelStoreError(f"manifest is incomplete: {exc}", where=where) from None


def save_model_dir(path: Path, manifest: ModelManifest, arrays: Mapping[str, np.ndarray]) -> None:
    """Write a model directory (created if needed, files replaced atomically)."""
    path.mkdir(parents=True, exist_ok=True)
    temp_arrays = path / (ARRAYS_NAME + ".tmp")
    with open(temp_arrays, "wb") as handle:
        contiguous: dict[str, Any] = {k: np.ascontiguousarray(v) for k, v in arrays.items()}
        np.savez(handle, **contiguous)
    temp_arrays.replace(path / ARRAYS_NAME)
    temp_manifest = path / (MANIFEST_NAME + ".tmp")
    temp_manifest.write_text(manifest.to_json() + "\n", encoding="utf-8")
    temp_manifest.replace(path / MANIFEST_NAME)


def read_manifest(path: Path) -> ModelManifest:
    """Read and check ``model.json`` of a model directory."""
    manifest_path = path / MANIFEST_NAME
    if not manifest_path.is_file():
        raise ModelStoreError("not a model directory (no model.json)", where=str(path))
    try:
        data = json.loads(manifest_path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ModelStoreError(
            f"model.json is not valid JSON: {exc}", where=str(manifest_path)
        ) from exc
    if not isinstance(data, dict):
        raise ModelStoreError("model.json must hold an object", where=str(manifest_path))
    return ModelManifest.from_mapping(data, str(manifest_path))


def _member_offset(raw: Any, info: zipfile.ZipInfo) -> int:
    raw.seek(info.header_offset)
    header = raw.read(_LOCAL_HEADER_SIZE)
    name_length = int.from_bytes(header[26:28], "little")
    extra_length = int.from_bytes(header[28:30], "little")
    return info.header_offset + _LOCAL_HEADER_SIZE + name_length + extra_length


def _map_member(path: Path, archive: zipfile.ZipFile, info: zipfile.ZipInfo) -> np.ndarray:
    if info.compress_type != zipfile.ZIP_STORED:
        raise ModelStoreError(f"array {info.filename} is compressed", where=str(path))
    with open(path, "rb") as raw:
        start = _member_offset(raw, info)
        raw.seek(start)
        version = np.lib.format.read_magic(raw)
        reader = (
            np.lib.format.read_array_header_1_0
            if version == (1, 0)
            else np.lib.format.read_array_header_2_0
        )
        shape, fortran_order, dtype = reader(raw)
        data_offset = raw.tell()
    if dtype.hasobject:
        raise ModelStoreError(f"array {info.filename} holds Python objects", where=str(path))
    if int(np.prod(shape)) == 0:
        return np.zeros(shape, dtype=dtype)
    mapped: np.ndarray = np.memmap(
        path,
        dtype=dtype,
        mode="r",
        offset=data_offset,
        shape=tuple(shape),
        order="F" if fortran_order else "C",
    )
    return mapped


def load_arrays(path: Path) -> dict[str, np.ndarray]:
    """Memory-map every array of ``arrays.npz`` read-only."""
    arrays_path = path / ARRAYS_NAME
    try:
        with zipfile.ZipFile(arrays_path) as archive:
            members = [info for info in archive.infolist() if info.filename.endswith(".npy")]
            return {
                info.filename[: -len(".npy")]: _map_member(arrays_path, archive, info)
                for info in members
            }
    except (OSError, zipfile.BadZipFile, ValueError) as exc:
        raise ModelStoreError(f"cannot read arrays: {exc}", where=str(arrays_path)) from None


def require_arrays(
    arrays: Mapping[str, np.ndarray], names: list[str], where: Path
) -> dict[str, np.ndarray]:
    """Pick the named arrays, with a clear error when one is missing."""
    missing = [name for name in names if name not in arrays]
    if missing:
        raise ModelStoreError(f"arrays.npz lacks {missing}", where=str(where / ARRAYS_NAME))
    return {name: arrays[name] for name in names}
