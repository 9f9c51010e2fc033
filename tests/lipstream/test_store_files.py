"""Issue 29, defect 8: ``arrays.npz`` may be anything. A model whose arrays file is a device,
a FIFO, a huge sparse file, or holds an array that claims more than the manifest declares is
refused with ``model_invalid`` naming the file, after reading no more than its headers.

Each load runs in a child process that counts the bytes it reads (``/proc/self/io``
``rchar``) and its resident memory around ``load_model``, under an address-space limit, so
a load that reads without limit fails (or is killed by the ``subprocess`` bound) instead of
taking the machine's memory.
"""

from __future__ import annotations

import json
import os
import struct
import subprocess
import sys
import zipfile
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pytest

from lipstream.store import ARRAYS_NAME, MANIFEST_NAME, load_arrays, read_manifest, save_model_dir

if TYPE_CHECKING:
    from lipstream.engines.base import Model

CHILD_BOUND_S = 300.0  # a bound for a hung load on a busy machine, not a speed claim
MAX_READ_BYTES = 1 << 20  # a refusal reads headers, never the arrays
MAX_RSS_GROWTH_MB = 64.0
SPARSE_BYTES = 3 << 30

_CHILD = r"""
import json, resource, sys
from pathlib import Path
from lipstream.engines import engine_names, get_engine_class
from lipstream.errors import LipstreamError
for name in engine_names():
    get_engine_class(name)
from lipstream.engines import load_model

def counter(field):
    for line in open(f"/proc/self/{'io' if field == 'rchar' else 'status'}"):
        if line.startswith(field):
            return int(line.split()[1])

headroom = 1 << 30
vm = counter("VmSize:") * 1024
resource.setrlimit(resource.RLIMIT_AS, (vm + headroom, vm + headroom))
read, rss = counter("rchar"), counter("VmRSS:")
try:
    load_model(Path(sys.argv[1]))
    result = {"code": None}
except LipstreamError as error:
    result = {"code": error.code, "where": error.where, "message": error.message}
result["read"] = counter("rchar") - read
result["rss_growth_mb"] = (counter("VmRSS:") - rss) / 1024
print(json.dumps(result))
"""


def _load_in_child(directory: Path) -> dict[str, Any]:
    done = subprocess.run(
        [sys.executable, "-c", _CHILD, str(directory)],
        capture_output=True,
        text=True,
        timeout=CHILD_BOUND_S,
        check=False,
        env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)},
    )
    assert done.returncode == 0, done.stderr[-3000:]
    result: dict[str, Any] = json.loads(done.stdout.splitlines()[-1])
    return result


def _assert_refused(directory: Path, where: str, message: str) -> None:
    result = _load_in_child(directory)
    assert result["code"] == "model_invalid", result
    assert result["where"] == where, result
    assert message in result["message"], result
    assert result["read"] < MAX_READ_BYTES, result
    assert result["rss_growth_mb"] < MAX_RSS_GROWTH_MB, result


@pytest.fixture
def lerp_model(trained_models: dict[str, Model], tmp_path: Path) -> Path:
    directory = tmp_path / "viseme-lerp"
    trained_models["viseme-lerp"].save(directory)
    return directory


def test_arrays_symlinked_to_dev_zero_are_refused(lerp_model: Path) -> None:
    arrays = lerp_model / ARRAYS_NAME
    arrays.unlink()
    arrays.symlink_to("/dev/zero")
    _assert_refused(lerp_model, str(arrays), "is not a regular file (a character device)")


def test_arrays_as_a_fifo_are_refused_without_waiting_for_a_writer(lerp_model: Path) -> None:
    arrays = lerp_model / ARRAYS_NAME
    arrays.unlink()
    os.mkfifo(arrays)
    _assert_refused(lerp_model, str(arrays), "is not a regular file (a FIFO)")


def test_a_manifest_that_is_a_fifo_is_refused(lerp_model: Path) -> None:
    manifest = lerp_model / MANIFEST_NAME
    manifest.unlink()
    os.mkfifo(manifest)
    _assert_refused(lerp_model, str(lerp_model), "not a model directory")


def _stored_zip(path: Path, name: str, header: bytes, data_bytes: int) -> None:
    """A stored (uncompressed) zip of one member, ``header`` then ``data_bytes`` of zeros
    left as a hole (a sparse file). The CRC is 0: no reader here checks it."""
    member = name.encode()
    size = len(header) + data_bytes
    local = struct.pack("<IHHHHHIIIHH", 0x04034B50, 20, 0, 0, 0, 0, 0, size, size, len(member), 0)
    central = struct.pack(
        "<IHHHHHHIIIHHHHHII",
        0x02014B50,
        20,
        20,
        0,
        0,
        0,
        0,
        0,
        size,
        size,
        len(member),
        0,
        0,
        0,
        0,
        0,
        0,
    )
    with open(path, "wb") as handle:
        handle.write(local + member + header)
        handle.seek(data_bytes, os.SEEK_CUR)
        directory_at = handle.tell()
        handle.write(central + member)
        directory_bytes = handle.tell() - directory_at
        handle.write(
            struct.pack("<IHHHHIIH", 0x06054B50, 0, 0, 1, 1, directory_bytes, directory_at, 0)
        )


def _npy_header(shape: tuple[int, ...], dtype: str) -> bytes:
    header = {"descr": dtype, "fortran_order": False, "shape": shape}
    text = repr(header).encode("latin-1")
    padding = 64 - (10 + len(text) + 1) % 64
    text += b" " * padding + b"\n"
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(text)) + text


def test_a_huge_sparse_arrays_file_is_refused_by_its_declared_size(lerp_model: Path) -> None:
    """A valid zip whose first array holds 3 GiB (a hole on disk): the manifest declares
    the real file's size, so the load refuses it before reading the array."""
    manifest = read_manifest(lerp_model)
    name = next(iter(manifest.array_data_bytes))
    arrays = lerp_model / ARRAYS_NAME
    _stored_zip(arrays, f"{name}.npy", _npy_header((SPARSE_BYTES // 4,), "<f4"), SPARSE_BYTES)
    with zipfile.ZipFile(arrays) as archive:
        assert archive.getinfo(f"{name}.npy").file_size > SPARSE_BYTES
    size = arrays.stat().st_size
    _assert_refused(
        lerp_model,
        str(arrays),
        f"is {size} bytes, the manifest declares {manifest.arrays_file_bytes}",
    )


def _patch_shape(arrays: Path, name: str, old: bytes, new: bytes) -> None:
    """Rewrite the shape in one member's .npy header in place (same length, same file size)."""
    raw = bytearray(arrays.read_bytes())
    with zipfile.ZipFile(arrays) as archive:
        offset = archive.getinfo(f"{name}.npy").header_offset
    at = raw.index(old, offset)
    assert len(old) == len(new)
    raw[at : at + len(old)] = new
    arrays.write_bytes(bytes(raw))


def test_an_array_claiming_more_than_the_manifest_declares_is_refused(tmp_path: Path) -> None:
    """The file keeps its declared size; one array's header claims twice its rows."""
    manifest = read_manifest(_saved_lerp_like(tmp_path))
    arrays = tmp_path / ARRAYS_NAME
    _patch_shape(arrays, "big", b"(16, 4)", b"(32, 4)")
    with pytest.raises(Exception) as caught:
        load_arrays(tmp_path, manifest.array_sizes)
    error = caught.value
    assert getattr(error, "code", None) == "model_invalid"
    assert getattr(error, "where", None) == f"{arrays}: big"
    assert "the manifest declares 256" in str(error)


def _saved_lerp_like(directory: Path) -> Path:
    from lipstream.store import ModelManifest

    manifest = ModelManifest("viseme-lerp", "demo", ["jawOpen"], 60.0, ["sil"])
    save_model_dir(directory, manifest, {"big": np.ones((16, 4), dtype=np.float32)})
    return directory


def test_an_array_claiming_more_than_its_member_stores_is_refused(tmp_path: Path) -> None:
    """Without declared sizes (a manifest older than them) an array must still lie inside
    its member: no mapping reaches past it."""
    _saved_lerp_like(tmp_path)
    arrays = tmp_path / ARRAYS_NAME
    _patch_shape(arrays, "big", b"(16, 4)", b"(96, 4)")
    with pytest.raises(Exception) as caught:
        load_arrays(tmp_path)
    assert getattr(caught.value, "where", None) == f"{arrays}: big"
    assert "more than its member stores (256)" in str(caught.value)


def test_saved_manifests_declare_their_sizes_and_old_ones_still_load(tmp_path: Path) -> None:
    _saved_lerp_like(tmp_path)
    manifest = read_manifest(tmp_path)
    assert manifest.arrays_file_bytes == (tmp_path / ARRAYS_NAME).stat().st_size
    assert manifest.array_data_bytes == {"big": 16 * 4 * 4}
    data = json.loads((tmp_path / MANIFEST_NAME).read_text())
    del data["arrays_file_bytes"], data["array_data_bytes"]
    (tmp_path / MANIFEST_NAME).write_text(json.dumps(data))
    old = read_manifest(tmp_path)
    assert old.array_sizes is None
    np.testing.assert_array_equal(load_arrays(tmp_path, old.array_sizes)["big"], np.ones((16, 4)))
