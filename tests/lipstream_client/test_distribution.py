"""``pip install ./client_sdk`` installs the client alone, and it works without numpy.

A fresh venv reaches only pip's build tools and the two packages the client
promises to need, msgpack and websockets (tests/venvs.py): pip installs a copy of
``client_sdk/`` alone, offline, and fails if the client requires anything else.
The installed client then imports, encodes and decodes frames against payloads
built here from the published format (docs/reference/protocol.md), ships its
schemas and ``py.typed``, and its VMC sink, whose python-osc is an extra, says so.
"""

from __future__ import annotations

import shutil
import tomllib
from pathlib import Path

import pytest

from tests.helpers import REPO
from tests.venvs import (
    BUILD_TOOLS,
    PIP_INSTALL,
    distributions_closure,
    isolated_environment,
    link_installed,
    new_venv,
    run,
    top_level_entries,
)

pytestmark = pytest.mark.slow

CLIENT_NEEDS = ("msgpack", "websockets")
USE_THE_CLIENT = r"""
import importlib.metadata, importlib.resources, importlib.util, json, struct, sys
import msgpack

assert importlib.util.find_spec("numpy") is None, "numpy is reachable"
import lipstream_client as client
from lipstream_client.sinks import BridgeError
from lipstream_client.sinks.vmc import frame_messages

published = {"v": 1, "type": "frames", "id": "a", "seq": 3, "first_frame": 7, "fps": 60.0,
             "n_channels": 2}
in_msgpack = msgpack.packb(published | {"data": struct.pack("<4f", 0.25, 0.5, 1.0, 0.0)})
frames = client.decode(in_msgpack, "msgpack")
assert (frames.id, frames.seq, frames.first_frame, frames.fps) == ("a", 3, 7, 60.0)
assert frames.rows() == [[0.25, 0.5], [1.0, 0.0]]
assert msgpack.unpackb(client.encode(frames, "msgpack")) == msgpack.unpackb(in_msgpack)
in_json = published | {"data": [[0.25, 0.5], [1.0, 0.0]]}
assert json.loads(client.encode(frames, "json")) == in_json
assert client.decode(json.dumps(in_json), "json") == frames

assert client.load_schema("frames")["$id"] == "urn:lipstream:protocol:v1:frames"
package = importlib.resources.files("lipstream_client")
print(sorted(path.name for path in (package / "schemas").iterdir()))
print((package / "py.typed").is_file(), client.__file__)
print(client.AsyncClient.__module__, client.Client.__module__)
try:
    frame_messages(["A"], 0.0, [0.5])
except BridgeError as error:
    print(error.code, error.where)
print(importlib.metadata.requires("lipstream-client"))
print(sorted(name for name in ("numpy", "pythonosc") if name in sys.modules))
"""


def test_the_client_installs_alone_and_works_without_numpy(tmp_path: Path) -> None:
    client_sdk = tmp_path / "client_sdk"
    shutil.copytree(
        REPO / "client_sdk",
        client_sdk,
        ignore=shutil.ignore_patterns("__pycache__", "*.egg-info", "build"),
    )
    reachable = top_level_entries(distributions_closure((*BUILD_TOOLS, *CLIENT_NEEDS)))
    assert not any(entry.startswith("numpy") for entry in reachable), sorted(reachable)
    packages = link_installed(tmp_path / "packages", lambda name: name in reachable)
    site_packages = new_venv(tmp_path / "venv", packages)
    python = str(tmp_path / "venv" / "bin" / "python")
    environment = isolated_environment()
    work = tmp_path / "work"
    work.mkdir()

    run(python, *PIP_INSTALL, str(client_sdk), env=environment, cwd=work)
    lines = run(python, "-c", USE_THE_CLIENT, env=environment, cwd=work).stdout.splitlines()

    shipped = sorted(path.name for path in (REPO / "client_sdk/lipstream_client/schemas").iterdir())
    assert len(shipped) == 12
    assert lines == [
        repr(shipped),
        f"True {site_packages / 'lipstream_client' / '__init__.py'}",
        "lipstream_client.client lipstream_client.sync",
        "missing_dependency sinks.vmc",
        repr(["msgpack>=1.0", "websockets>=12", 'python-osc>=1.8; extra == "vmc"']),
        "[]",
    ]
    assert not (site_packages / "lipstream").exists()


def test_the_server_requires_the_client_of_its_own_checkout() -> None:
    server = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))
    client = tomllib.loads((REPO / "client_sdk" / "pyproject.toml").read_text(encoding="utf-8"))
    version = client["project"]["version"]
    assert client["project"]["name"] == "lipstream-client"
    assert f"lipstream-client[vmc]=={version}" in server["project"]["dependencies"]
    assert server["tool"]["setuptools"]["packages"]["find"]["where"] == ["server"]
    assert "lipstream_client" not in server["tool"]["setuptools"]["package-data"]
