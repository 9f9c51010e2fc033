"""ruff runs on the code: a lint finding anywhere in the packages or tests fails the suite."""

from __future__ import annotations

import subprocess
import sys

from tests.helpers import REPO


def test_packages_lint_clean() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "ruff", "check", "server", "client_sdk", "tests"],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stdout + result.stderr


def test_one_formatter_keeps_the_tree_formatted() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "ruff", "format", "--check", "server", "client_sdk", "tests"],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stdout + result.stderr
