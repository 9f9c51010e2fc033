"""README command (a)'s install and first start, then command (b)'s install, in one venv.

Command (a) installs the package (``pip install .``) and its first start compiles the
kernels numba caches; command (b) then installs the same checkout in editable mode
(``pip install -e``). Numba's cache once went beside the installed source files, so the
uninstall left a ``site-packages/lipstream`` folder without ``__init__.py`` that hid the
editable install. Here both installs are pip's own, into one fresh venv, of a copy of the
checkout: ``--no-deps --no-build-isolation --no-index``, with the running environment's
packages (less this project) reachable through a ``.pth`` file, so nothing is downloaded.
The first start is reduced to what writes the cache: compiling one ``cache=True`` kernel.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

from tests.helpers import REPO

pytestmark = pytest.mark.slow

CHECKOUT_PARTS = ("pyproject.toml", "README.md", "server", "client_sdk")
PIP_INSTALL = ("-m", "pip", "install", "--no-deps", "--no-build-isolation", "--no-index")
FIRST_COMPILE = (
    "import numpy as np\n"
    "from lipstream.numerics.banded import _all_finite\n"
    "assert _all_finite(np.ones(3)) and not _all_finite(np.array([1.0, np.nan]))\n"
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


def _dependencies_without_lipstream(destination: Path) -> Path:
    """A folder of links to this environment's installed packages, less lipstream's own
    install (its metadata and editable finder), for the new venv to reach through a .pth."""
    destination.mkdir()
    for entry in Path(sysconfig.get_paths()["purelib"]).iterdir():
        name = entry.name.lower()
        if name.startswith(("lipstream", "__editable__")) or name.endswith(".pth"):
            continue
        (destination / entry.name).symlink_to(entry)
    return destination


def _new_venv(directory: Path, dependencies: Path) -> Path:
    subprocess.run(
        [sys.executable, "-m", "venv", "--without-pip", str(directory)],
        check=True,
        capture_output=True,
    )
    python = directory / "bin" / "python"
    purelib = subprocess.run(
        [str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout.strip()
    (Path(purelib) / "_dependencies.pth").write_text(f"{dependencies}\n")
    return Path(purelib)


def _run(*argv: str, env: dict[str, str], cwd: Path) -> subprocess.CompletedProcess[str]:
    finished = subprocess.run(argv, env=env, cwd=cwd, capture_output=True, text=True)
    assert finished.returncode == 0, (
        f"{' '.join(argv)} exited {finished.returncode}:\n{finished.stdout}\n{finished.stderr}"
    )
    return finished


def test_command_a_then_command_b_in_one_checkout(tmp_path: Path) -> None:
    checkout = _copy_checkout(tmp_path / "checkout")
    site_packages = _new_venv(
        tmp_path / "venv", _dependencies_without_lipstream(tmp_path / "dependencies")
    )
    python = str(tmp_path / "venv" / "bin" / "python")
    home = tmp_path / "home"
    environment = {
        name: value
        for name, value in os.environ.items()
        if not name.startswith(("PYTHON", "PIP_", "NUMBA_", "LIPSTREAM_"))
    }
    environment |= {"LIPSTREAM_HOME": str(home), "PIP_DISABLE_PIP_VERSION_CHECK": "1"}
    work = tmp_path / "work"
    work.mkdir()

    _run(python, *PIP_INSTALL, str(checkout), env=environment, cwd=checkout)
    installed = site_packages / "lipstream"
    assert (installed / "__init__.py").is_file()
    _run(python, "-c", FIRST_COMPILE, env=environment, cwd=work)
    written = [path for path in installed.rglob("*") if path.suffix in (".nbi", ".nbc")]
    assert written == [], f"numba wrote into the installed package: {written}"
    cached = [path.name for path in home.rglob("*") if path.suffix in (".nbi", ".nbc")]
    assert any(name.startswith("banded._all_finite") for name in cached), cached

    _run(python, *PIP_INSTALL, "-e", str(checkout), env=environment, cwd=checkout)
    assert not installed.exists(), sorted(map(str, installed.rglob("*")))
    imported = _run(
        python,
        "-c",
        "import lipstream; print(lipstream.__file__); print(callable(lipstream.load_model))",
        env=environment,
        cwd=work,
    ).stdout.split()
    assert imported == [str(checkout / "server" / "lipstream" / "__init__.py"), "True"]
    demo = _run(
        str(tmp_path / "venv" / "bin" / "lipstream"), "path", "demo", env=environment, cwd=work
    )
    assert demo.stdout.strip() == str(home / "demo" / "models")
    _run(python, "-c", FIRST_COMPILE, env=environment, cwd=work)
    assert not list((checkout / "server").rglob("*.nbi")), "numba wrote into the checkout"
