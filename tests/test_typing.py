"""Strict mypy runs on the packages and on tests/: a type error anywhere fails the suite."""

from __future__ import annotations

import subprocess
import sys

from tests.helpers import REPO


def test_packages_type_check() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "mypy"], cwd=REPO, capture_output=True, text=True, timeout=600
    )
    assert result.returncode == 0, result.stdout + result.stderr
