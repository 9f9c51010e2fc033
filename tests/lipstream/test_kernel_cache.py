"""Where numba caches lipstream's compiled kernels: the settings' folder, never the source's."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from lipstream.config import kernel_cache_dir

VERSIONS = (
    "import sys, importlib.metadata as m; "
    "print(m.version('lipstream'), f'{sys.version_info[0]}.{sys.version_info[1]}', "
    "m.version('numba'))"
)
CACHE_OF_A_KERNEL = (
    "import numpy as np\n"
    "from lipstream.numerics.banded import _all_finite\n"
    "assert _all_finite(np.ones(2))\n"
    "print(_all_finite._cache._cache_path)\n"
)


def _environment(**settings: str) -> dict[str, str]:
    environment = {
        name: value
        for name, value in os.environ.items()
        if not name.startswith(("NUMBA_", "LIPSTREAM_"))
    }
    return environment | settings


def _python(code: str, environment: dict[str, str]) -> str:
    finished = subprocess.run(
        [sys.executable, "-c", code], env=environment, capture_output=True, text=True, check=False
    )
    assert finished.returncode == 0, finished.stderr
    return finished.stdout.strip()


def _expected_folder(home: Path) -> Path:
    lipstream, python, numba = _python(VERSIONS, _environment()).split()
    return home / "numba-cache" / f"lipstream-{lipstream}-py{python}-numba{numba}"


def test_the_cache_is_under_lipstream_home(tmp_path: Path) -> None:
    assert kernel_cache_dir({"LIPSTREAM_HOME": str(tmp_path)}) == _expected_folder(tmp_path)


def test_without_lipstream_home_the_cache_is_under_the_user_cache(tmp_path: Path) -> None:
    cache = tmp_path / "xdg"
    expected = _expected_folder(cache / "lipstream")
    assert kernel_cache_dir({"XDG_CACHE_HOME": str(cache)}) == expected


def test_numba_cache_dir_wins(tmp_path: Path) -> None:
    chosen = tmp_path / "numba"
    environ = {"LIPSTREAM_HOME": str(tmp_path / "home"), "NUMBA_CACHE_DIR": str(chosen)}
    assert kernel_cache_dir(environ) == chosen


def test_a_compiled_kernel_is_cached_in_the_settings_folder(tmp_path: Path) -> None:
    home = tmp_path / "home"
    used = Path(_python(CACHE_OF_A_KERNEL, _environment(LIPSTREAM_HOME=str(home))))
    assert used.is_relative_to(_expected_folder(home))
    assert [path.name for path in used.glob("banded._all_finite-*.nbi")]


def test_numba_imported_before_lipstream_still_caches_there(tmp_path: Path) -> None:
    home = tmp_path / "home"
    code = "import numba\n" + CACHE_OF_A_KERNEL
    used = Path(_python(code, _environment(LIPSTREAM_HOME=str(home))))
    assert used.is_relative_to(_expected_folder(home))


def test_an_explicit_numba_cache_dir_is_kept_and_inherited(tmp_path: Path) -> None:
    chosen = tmp_path / "chosen"
    code = (
        "import os, subprocess, sys, lipstream\n"
        "print(os.environ['NUMBA_CACHE_DIR'])\n"
        "child = 'import numba; print(numba.config.CACHE_DIR)'\n"
        "print(subprocess.run([sys.executable, '-c', child], capture_output=True, text=True)"
        ".stdout.strip())\n"
    )
    lines = _python(code, _environment(NUMBA_CACHE_DIR=str(chosen))).splitlines()
    assert lines == [str(chosen), str(chosen)]


def test_processes_started_by_lipstream_inherit_the_folder(tmp_path: Path) -> None:
    home = tmp_path / "home"
    code = (
        "import subprocess, sys, lipstream\n"
        "child = 'import numba; print(numba.config.CACHE_DIR)'\n"
        "print(subprocess.run([sys.executable, '-c', child], capture_output=True, text=True)"
        ".stdout.strip())\n"
    )
    assert Path(_python(code, _environment(LIPSTREAM_HOME=str(home)))) == _expected_folder(home)
