"""The model store: one directory per trained model, shared by training and serving.

Layout of a model directory::

    model.json     manifest: schema version, engine, channels, fps, phoneme set,
                   hyperparameters, training-corpus digest, training metrics, and
                   the sizes of arrays.npz and of each array's data
    arrays.npz     uncompressed arrays

The ``.npz`` members are stored uncompressed, so each one is memory-mapped in
place (``mmap_mode="r"`` semantics): worker processes that load the same model
share its pages. No pickle is ever written or read.

A load reads no more than the manifest declares: both files are opened once
and must be regular files (a symlink is followed, but what it leads to must be
a regular file: a device such as ``/dev/zero`` or a FIFO is refused before any
byte is read); ``arrays.npz`` must be exactly ``arrays_file_bytes`` long and
each array's header must claim exactly its ``array_data_bytes`` entry, and lie
inside its member, before it is mapped. Manifests written before these fields
existed declare nothing (``arrays_file_bytes`` 0): their arrays are still
checked to lie inside the file.

Reading is defensive, as a model directory may be damaged or hand-edited:
``model.json`` is bounded in size and nesting and refuses NaN and Infinity, and
every manifest field is type-checked (``lipstream.model_checks``), so a bad
field is a ``model_invalid`` error naming the file and the field, never a raw
exception. Each engine's ``from_arrays`` checks the arrays it reads.
"""

from __future__ import annotations

import json
import math
import os
import stat
import struct
import zipfile
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import IO, Any

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
MAX_ARRAYS_BYTES = 1 << 40
"""The largest size a manifest may declare (1 TiB): a bound on the field, not a budget."""
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
    arrays_file_bytes: int = 0
    """The size of ``arrays.npz`` (0: not declared, a manifest older than the field)."""
    array_data_bytes: dict[str, int] = field(default_factory=dict)
    """Each array's data bytes (shape x item size), by name."""

    @property
    def array_sizes(self) -> ArraySizes | None:
        """What the manifest declares of ``arrays.npz``; None when it declares nothing."""
        if not self.arrays_file_bytes:
            return None
        return ArraySizes(self.arrays_file_bytes, self.array_data_bytes)

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
            arrays_file_bytes=fields.integer(
                data.get("arrays_file_bytes", 0), "arrays_file_bytes", 0, MAX_ARRAYS_BYTES
            ),
            array_data_bytes=_sizes(fields, data.get("array_data_bytes", {}), "array_data_bytes"),
        )


@dataclass(frozen=True)
class ArraySizes:
    """The declared size of ``arrays.npz`` and of each array's data, in bytes."""

    file_bytes: int
    members: Mapping[str, int]


def _sizes(fields: FieldReader, value: Any, field: str) -> dict[str, int]:
    sizes = fields.mapping(value, field)
    return {
        name: fields.integer(size, f"{field}.{name}", 0, MAX_ARRAYS_BYTES)
        for name, size in sizes.items()
    }


def _text(fields: FieldReader, data: Mapping[str, Any], key: str) -> str:
    """An optional free-text field (may be empty)."""
    value = data.get(key, "")
    if not isinstance(value, str):
        raise fields.error(key, f"must be a string, got {type(value).__name__}")
    return value


def save_model_dir(path: Path, manifest: ModelManifest, arrays: Mapping[str, np.ndarray]) -> None:
    """Write a model directory (created if needed, files replaced atomically); the manifest
    written declares the sizes of ``arrays.npz`` and of each array."""
    path.mkdir(parents=True, exist_ok=True)
    temp_arrays = path / (ARRAYS_NAME + ".tmp")
    with open(temp_arrays, "wb") as handle:
        contiguous: dict[str, Any] = {k: np.ascontiguousarray(v) for k, v in arrays.items()}
        np.savez(handle, **contiguous)
    manifest = replace(
        manifest,
        arrays_file_bytes=temp_arrays.stat().st_size,
        array_data_bytes={name: int(array.nbytes) for name, array in contiguous.items()},
    )
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
        with open_regular(manifest_path) as handle:
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


def open_regular(path: Path) -> IO[bytes]:
    """``path`` opened for reading; ``model_invalid`` naming it unless it is (or a symlink
    leads to) a regular file. Opened without blocking and checked on the descriptor, so a
    FIFO does not wait for a writer and nothing changes between the check and the reads."""
    try:
        descriptor = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        raise ModelStoreError(f"cannot open: {exc.strerror}", where=str(path)) from None
    mode = os.fstat(descriptor).st_mode
    if not stat.S_ISREG(mode):
        os.close(descriptor)
        raise ModelStoreError(
            f"is not a regular file ({_file_kind(mode)}); a model's files must be regular "
            "files, or symlinks to regular files",
            where=str(path),
        )
    os.set_blocking(descriptor, True)
    return os.fdopen(descriptor, "rb")


def _file_kind(mode: int) -> str:
    kinds = (
        (stat.S_ISDIR, "a directory"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISFIFO, "a FIFO"),
        (stat.S_ISSOCK, "a socket"),
    )
    return next((name for test, name in kinds if test(mode)), "a special file")


def _member_offset(raw: IO[bytes], info: zipfile.ZipInfo) -> int:
    raw.seek(info.header_offset)
    header = raw.read(_LOCAL_HEADER_SIZE)
    name_length = int.from_bytes(header[26:28], "little")
    extra_length = int.from_bytes(header[28:30], "little")
    return info.header_offset + _LOCAL_HEADER_SIZE + name_length + extra_length


def _map_member(
    raw: IO[bytes], where: str, info: zipfile.ZipInfo, declared: int | None
) -> np.ndarray:
    """The member's array, memory-mapped once its header is read and checked: stored, no
    objects, its data inside the member and the file, and (``declared``) exactly that many
    bytes. ``where`` names the file and the array."""
    if info.compress_type != zipfile.ZIP_STORED:
        raise ModelStoreError(f"array {info.filename} is compressed", where=where)
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
        raise ModelStoreError(f"array {info.filename} holds Python objects", where=where)
    n_bytes = math.prod(shape) * dtype.itemsize
    if declared is not None and n_bytes != declared:
        raise ModelStoreError(
            f"claims {n_bytes} bytes of data (shape {tuple(shape)}, {dtype.str}), the "
            f"manifest declares {declared}",
            where=where,
        )
    member_end = min(start + info.file_size, os.fstat(raw.fileno()).st_size)
    if data_offset + n_bytes > member_end:
        raise ModelStoreError(
            f"claims {n_bytes} bytes of data (shape {tuple(shape)}, {dtype.str}), more than "
            f"its member stores ({max(0, member_end - data_offset)})",
            where=where,
        )
    if n_bytes == 0:
        return np.zeros(shape, dtype=dtype)
    mapped: np.ndarray = np.memmap(
        raw,
        dtype=dtype,
        mode="r",
        offset=data_offset,
        shape=tuple(shape),
        order="F" if fortran_order else "C",
    )
    return mapped


def load_arrays(path: Path, sizes: ArraySizes | None = None) -> dict[str, np.ndarray]:
    """Memory-map every array of ``arrays.npz`` read-only; with ``sizes`` (the manifest's
    ``array_sizes``), the file and every array must be exactly the declared size, checked
    before they are read."""
    arrays_path = path / ARRAYS_NAME
    where = str(arrays_path)
    with open_regular(arrays_path) as raw:
        file_bytes = os.fstat(raw.fileno()).st_size
        if sizes is not None and file_bytes != sizes.file_bytes:
            raise ModelStoreError(
                f"is {file_bytes} bytes, the manifest declares {sizes.file_bytes}", where=where
            )
        try:
            with zipfile.ZipFile(raw) as archive:
                members = [info for info in archive.infolist() if info.filename.endswith(".npy")]
                arrays: dict[str, np.ndarray] = {}
                for info in members:
                    name = info.filename[: -len(".npy")]
                    if sizes is not None and name not in sizes.members:
                        raise ModelStoreError(
                            "is not declared by the manifest's array_data_bytes",
                            where=f"{where}: {name}",
                        )
                    declared = None if sizes is None else sizes.members[name]
                    arrays[name] = _map_member(raw, f"{where}: {name}", info, declared)
        except _ARCHIVE_ERRORS as exc:
            raise ModelStoreError(f"cannot read arrays: {exc}", where=where) from None
    if sizes is not None and set(sizes.members) - set(arrays):
        missing = sorted(set(sizes.members) - set(arrays))
        raise ModelStoreError(
            f"lacks arrays the manifest declares: {missing[:10]}", where=f"{where}: {missing[0]}"
        )
    return arrays


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
