"""README command (a)'s install and first start, then command (b)'s install, in one venv.

Command (a) installs the client SDK and the server from the checkout (``pip install
./client_sdk .``) and its first start compiles the kernels numba caches; command (b)
then installs the same checkout in editable mode (``pip install -e ./client_sdk -e
".[test]"``). Numba's cache once went beside the installed source files, so the
uninstall left a ``site-packages/lipstream`` folder without ``__init__.py`` that hid the
editable install. Here both installs are pip's own, with README's arguments, into one
fresh venv of a copy of the checkout, offline (tests/venvs.py): pip resolves the
server's ``lipstream-client`` requirement to ``./client_sdk``, which no index offers, and
every other one to this environment's packages (less this project's own installs). The
first start is reduced to what writes the cache: compiling one ``cache=True`` kernel.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from tests.helpers import REPO
from tests.venvs import (
    PIP_INSTALL,
    isolated_environment,
    link_installed,
    new_venv,
    readme_pip_arguments,
    run,
)

pytestmark = pytest.mark.slow

CHECKOUT_PARTS = ("pyproject.toml", "README.md", "server", "client_sdk")
FIRST_COMPILE = (
    "import numpy as np\n"
    "from lipstream.numerics.banded import _all_finite\n"
    "assert _all_finite(np.ones(3)) and not _all_finite(np.array([1.0, np.nan]))\n"
)
# where both packages import from, and a schema the server reads through the client package
WHERE_FROM = (
    "import json, lipstream, lipstream_client\n"
    "from lipstream.server.openapi import components\n"
    "print(lipstream.__file__, lipstream_client.__file__, callable(lipstream.load_model))\n"
    "print(json.dumps(components()['lipstream_fps'], sort_keys=True))\n"
)


def _copy_checkout(destination: Path) -> Path:
    destination.mkdir()
    ignore = shutil.ignore_patterns("__pycache__", "*.egg-info", "build")
    for part in CHECKOUT_PARTS:
        source = REPO / part
        if source.is_dir():
            shutil.copytree(source, destination / part, ignore=ignore)
        else:
            shutil.copy2(source, destination / part)
    return destination


def _not_this_project(name: str) -> bool:
    """Not lipstream's or lipstream-client's install (metadata, folders, editable finders)."""
    return not name.startswith(("lipstream", "__editable__"))


def _where_from(python: str, environment: dict[str, str], work: Path) -> list[str]:
    return run(python, "-c", WHERE_FROM, env=environment, cwd=work).stdout.split("\n")


def test_command_a_then_command_b_in_one_checkout(tmp_path: Path) -> None:
    checkout = _copy_checkout(tmp_path / "checkout")
    site_packages = new_venv(
        tmp_path / "venv", link_installed(tmp_path / "dependencies", _not_this_project)
    )
    python = str(tmp_path / "venv" / "bin" / "python")
    home = tmp_path / "home"
    environment = isolated_environment(LIPSTREAM_HOME=str(home))
    work = tmp_path / "work"
    work.mkdir()
    start_schema = checkout / "client_sdk" / "lipstream_client" / "schemas" / "start.json"
    fps_schema = json.loads(start_schema.read_text(encoding="utf-8"))["$defs"]["fps"]

    command_a = readme_pip_arguments("a")
    assert "./client_sdk" in command_a, command_a
    run(python, *PIP_INSTALL, *command_a, env=environment, cwd=checkout)
    installed = site_packages / "lipstream"
    installed_client = site_packages / "lipstream_client"
    assert (installed / "__init__.py").is_file()
    assert (installed_client / "py.typed").is_file()
    assert len(list((installed_client / "schemas").glob("*.json"))) == 12
    assert not (installed / "schemas").exists()
    assert _where_from(python, environment, work)[:2] == [
        f"{installed / '__init__.py'} {installed_client / '__init__.py'} True",
        json.dumps(fps_schema, sort_keys=True),
    ]
    run(python, "-c", FIRST_COMPILE, env=environment, cwd=work)
    written = [path for path in installed.rglob("*") if path.suffix in (".nbi", ".nbc")]
    assert written == [], f"numba wrote into the installed package: {written}"
    cached = [path.name for path in home.rglob("*") if path.suffix in (".nbi", ".nbc")]
    assert any(name.startswith("banded._all_finite") for name in cached), cached

    run(python, *PIP_INSTALL, *readme_pip_arguments("b"), env=environment, cwd=checkout)
    assert not installed.exists(), sorted(map(str, installed.rglob("*")))
    assert not installed_client.exists(), sorted(map(str, installed_client.rglob("*")))
    assert _where_from(python, environment, work)[:2] == [
        f"{checkout / 'server' / 'lipstream' / '__init__.py'} "
        f"{checkout / 'client_sdk' / 'lipstream_client' / '__init__.py'} True",
        json.dumps(fps_schema, sort_keys=True),
    ]
    demo = run(
        str(tmp_path / "venv" / "bin" / "lipstream"), "path", "demo", env=environment, cwd=work
    )
    assert demo.stdout.strip() == str(home / "demo" / "models")
    run(python, "-c", FIRST_COMPILE, env=environment, cwd=work)
    assert not list((checkout / "server").rglob("*.nbi")), "numba wrote into the checkout"
