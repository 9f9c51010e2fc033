"""mypy runs on the code: a type error anywhere in the packages fails the suite."""

from __future__ import annotations

import subprocess
import sys

from tests.helpers import REPO


def test_packages_type_check() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "mypy"], cwd=REPO, capture_output=True, text=True, timeout=600
    )
    assert result.returncode == 0, result.stdout + result.stderr
