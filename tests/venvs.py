"""Fresh virtual environments for the install tests, with nothing downloaded.

A venv is made ``--without-pip``; the packages it may use (pip and the build tools
among them) are this environment's installed ones, linked into a folder that a
``.pth`` file puts on its path. pip then installs from a checkout with
``--no-index --no-build-isolation``, so it resolves every dependency against what
is linked, and fails on one that is not.
"""

from __future__ import annotations

import os
import shlex
import subprocess
import sys
import sysconfig
from collections.abc import Callable, Iterable
from importlib.metadata import Distribution, distribution
from pathlib import Path

from packaging.requirements import Requirement

from tests.helpers import REPO

PIP_INSTALL = ("-m", "pip", "install", "--no-build-isolation", "--no-index")
BUILD_TOOLS = ("pip", "setuptools", "wheel")


def link_installed(destination: Path, keep: Callable[[str], bool]) -> Path:
    """A folder of links to the entries of this environment's site-packages whose
    lower-cased names ``keep`` accepts (``.pth`` files never: they run code)."""
    destination.mkdir()
    for entry in Path(sysconfig.get_paths()["purelib"]).iterdir():
        name = entry.name.lower()
        if keep(name) and not name.endswith(".pth"):
            (destination / entry.name).symlink_to(entry)
    return destination


def distributions_closure(names: Iterable[str]) -> list[Distribution]:
    """The installed distributions ``names`` and, recursively, what they require
    (extras left out, environment markers evaluated here)."""
    found: dict[str, Distribution] = {}
    pending = list(names)
    while pending:
        name = pending.pop()
        installed = distribution(name)
        key = installed.metadata["Name"].lower().replace("_", "-")
        if key in found:
            continue
        found[key] = installed
        for text in installed.requires or []:
            requirement = Requirement(text)
            if requirement.marker is None or requirement.marker.evaluate({"extra": ""}):
                pending.append(requirement.name)
    return list(found.values())


def top_level_entries(distributions: Iterable[Distribution]) -> set[str]:
    """The site-packages entries (packages, modules, ``.dist-info``) the distributions
    installed, lower-cased."""
    entries: set[str] = set()
    for installed in distributions:
        for file in installed.files or []:
            top = file.parts[0]
            if top not in ("..", "__pycache__"):
                entries.add(top.lower())
    return entries


def new_venv(directory: Path, packages: Path) -> Path:
    """A venv at ``directory`` that reaches ``packages`` through a ``.pth``; its purelib."""
    subprocess.run(
        [sys.executable, "-m", "venv", "--without-pip", str(directory)],
        check=True,
        capture_output=True,
    )
    purelib = subprocess.run(
        [
            str(directory / "bin" / "python"),
            "-c",
            "import sysconfig; print(sysconfig.get_paths()['purelib'])",
        ],
        check=True,
        capture_output=True,
        text=True,
    ).stdout.strip()
    (Path(purelib) / "_dependencies.pth").write_text(f"{packages}\n")
    return Path(purelib)


def isolated_environment(**settings: str) -> dict[str, str]:
    """This process's environment less what would reach into it (``PYTHONPATH``, pip's,
    numba's and lipstream's settings), plus ``settings``."""
    environment = {
        name: value
        for name, value in os.environ.items()
        if not name.startswith(("PYTHON", "PIP_", "NUMBA_", "LIPSTREAM_"))
    }
    return environment | {"PIP_DISABLE_PIP_VERSION_CHECK": "1"} | settings


def run(*argv: str, env: dict[str, str], cwd: Path) -> subprocess.CompletedProcess[str]:
    finished = subprocess.run(argv, env=env, cwd=cwd, capture_output=True, text=True)
    assert finished.returncode == 0, (
        f"{' '.join(argv)} exited {finished.returncode}:\n{finished.stdout}\n{finished.stderr}"
    )
    return finished


def readme_pip_arguments(command: str) -> list[str]:
    """What README command ``command`` ("a" or "b") passes to ``.venv/bin/pip install``."""
    lines = (REPO / "README.md").read_text(encoding="utf-8").splitlines()
    marker = lines.index(f"<!-- command-{command} -->")
    for step in lines[marker + 2].split("&&"):
        words = shlex.split(step)
        if words[:2] == [".venv/bin/pip", "install"]:
            return words[2:]
    raise AssertionError(f"README command ({command}) runs no .venv/bin/pip install")
