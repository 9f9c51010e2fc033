"""The model store: one directory per trained model, shared by training and serving.

Layout of a model directory::

    model.json     manifest: schema version, engine, channels, fps, phoneme set,
                   hyperparameters, training-corpus digest, training metrics
    arrays.npz     uncompressed arrays

The ``.npz`` members are stored uncompressed, so each one is memory-mapped in
place (``mmap_mode="r"`` semantics): worker processes that load the same model
share its pages. No pickle is ever written or read.

Reading is defensive, as a model directory may be damaged or hand-edited:
``model.json`` is bounded in size and nesting and refuses NaN and Infinity, and
every manifest field is type-checked (``lipstream.model_checks``), so a bad
field is a ``model_invalid`` error naming the file and the field, never a raw
exception. Each engine's ``from_arrays`` checks the arrays it reads.
"""

from __future__ import annotations

import json
import struct
import zipfile
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .errors import ModelStoreError
from .model_checks import FieldReader

SCHEMA_VERSION = 1
MANIFEST_NAME = "model.json"
ARRAYS_NAME = "arrays.npz"
MAX_FPS = 1000.0
"""Highest frame rate of a stored model or a request, in Hz."""
MAX_MANIFEST_BYTES = 4 << 20
MAX_MANIFEST_DEPTH = 32
_LOCAL_HEADER_SIZE = 30
_REQUIRED_FIELDS = ("engine", "name", "channels", "fps", "phoneme_set")
_ARCHIVE_ERRORS = (
    OSError,
    EOFError,
    ValueError,
    TypeError,
    SyntaxError,
    OverflowError,
    NotImplementedError,
    RuntimeError,
    struct.error,
    zipfile.BadZipFile,
    zipfile.LargeZipFile,
)


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
        """The manifest of ``data`` (read from the file ``where``), every field type-checked;
        ``model_invalid`` naming the field otherwise."""
        version = data.get("schema_version")
        if isinstance(version, bool) or version != SCHEMA_VERSION:
            raise ModelStoreError(
                f"schema version {version!r} is not supported (this lipstream reads "
                f"version {SCHEMA_VERSION}); retrain the model with `lipstream train`",
                where=where,
                code="model_schema_version",
            )
        known = set(cls.__dataclass_fields__)
        unknown = sorted(set(data) - known)
        if unknown:
            raise ModelStoreError(f"unknown manifest keys {unknown[:10]}", where=where)
        fields = FieldReader(where)
        for key in _REQUIRED_FIELDS:
            fields.member(data, key, key)
        return cls(
            engine=fields.string(data["engine"], "engine"),
            name=fields.string(data["name"], "name"),
            channels=fields.strings(data["channels"], "channels", unique=True, min_count=1),
            fps=fields.number(data["fps"], "fps", 0.0, MAX_FPS, above=True),
            phoneme_set=fields.strings(data["phoneme_set"], "phoneme_set", unique=True),
            hyperparameters=dict(
                fields.mapping(data.get("hyperparameters", {}), "hyperparameters")
            ),
            corpus_digest=_text(fields, data, "corpus_digest"),
            metrics=dict(fields.mapping(data.get("metrics", {}), "metrics")),
            extra=dict(fields.mapping(data.get("extra", {}), "extra")),
            lipstream_version=_text(fields, data, "lipstream_version"),
        )


def _text(fields: FieldReader, data: Mapping[str, Any], key: str) -> str:
    """An optional free-text field (may be empty)."""
    value = data.get(key, "")
    if not isinstance(value, str):
        raise fields.error(key, f"must be a string, got {type(value).__name__}")
    return value


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
    if not path.is_dir():
        reason = "not a directory" if path.exists() else "no such directory"
        raise ModelStoreError(reason, where=str(path))
    if not manifest_path.is_file():
        raise ModelStoreError("not a model directory (no model.json)", where=str(path))
    where = str(manifest_path)
    try:
        with open(manifest_path, "rb") as handle:
            raw = handle.read(MAX_MANIFEST_BYTES + 1)
    except OSError as exc:
        raise ModelStoreError(f"cannot read model.json: {exc}", where=where) from None
    if len(raw) > MAX_MANIFEST_BYTES:
        raise ModelStoreError(f"model.json is larger than {MAX_MANIFEST_BYTES} bytes", where=where)
    try:
        data = json.loads(raw.decode("utf-8"), parse_constant=_refuse_constant)
    except RecursionError:
        raise ModelStoreError("model.json is nested too deeply", where=where) from None
    except (ValueError, UnicodeDecodeError) as exc:
        raise ModelStoreError(f"model.json is not valid JSON: {exc}", where=where) from None
    if not isinstance(data, dict):
        raise ModelStoreError("model.json must hold an object", where=where)
    _check_depth(data, where)
    return ModelManifest.from_mapping(data, where)


def _refuse_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a JSON number")


def _check_depth(data: Any, where: str) -> None:
    """Refuse lists and objects nested more than ``MAX_MANIFEST_DEPTH`` deep (walked without
    recursion), so no later reader of the manifest recurses without bound."""
    level: list[Any] = [data]
    for _ in range(MAX_MANIFEST_DEPTH):
        level = [
            child
            for value in level
            for child in (value.values() if isinstance(value, dict) else value)
            if isinstance(child, (dict, list))
        ]
        if not level:
            return
    raise ModelStoreError(
        f"model.json nests lists and objects more than {MAX_MANIFEST_DEPTH} deep", where=where
    )


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
    except _ARCHIVE_ERRORS as exc:
        raise ModelStoreError(f"cannot read arrays: {exc}", where=str(arrays_path)) from None


def require_arrays(
    arrays: Mapping[str, np.ndarray], names: list[str], where: Path
) -> dict[str, np.ndarray]:
    """Pick the named arrays, with a clear error when one is missing."""
    missing = [name for name in names if name not in arrays]
    if missing:
        raise ModelStoreError(
            f"is missing (arrays.npz lacks {missing})", where=f"{where / ARRAYS_NAME}: {missing[0]}"
        )
    return {name: arrays[name] for name in names}
