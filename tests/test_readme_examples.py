"""The README's examples, and the docs' marked ones, run as written, against a small
trained demo in a temporary home.

Each example block is marked with an HTML comment: ``<!-- example: offline -->``
runs with only ``LIPSTREAM_HOME`` pointing at the demo models, ``<!-- example:
server -->`` runs against a live loopback server of those models (its URL
replaces ``127.0.0.1:8000``/``localhost:8000``). Blocks run with the checkout's
layout: ``.venv`` (this interpreter's environment), ``examples/``,
``client_sdk/``. A ``print`` whose line ends in ``# expected output`` must print
that (``...`` matches anything).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from lipstream.engines.base import Model
from tests.helpers import REPO
from tests.live_server import LiveServer, live_server, save_models

README = (REPO / "README.md").read_text(encoding="utf-8")
MARKED = re.compile(r"<!-- example: (offline|server) -->\n```(python|bash)\n(.*?)```", re.DOTALL)
FENCE = re.compile(r"^```(python|bash)$", re.MULTILINE)
DEFAULT_SERVER = re.compile(r"(127\.0\.0\.1|localhost):8000")
RUN_LIMIT_S = 120
OUT = "out"  # the folder the README's command-line examples write into


@dataclass(frozen=True)
class Example:
    where: str
    language: str
    code: str

    @property
    def label(self) -> str:
        first = self.code.strip().splitlines()[0]
        return f"{self.where}-{self.language}-{first[:40]}"


DOCS = [README] + [
    path.read_text(encoding="utf-8") for path in sorted((REPO / "docs").rglob("*.md"))
]
EXAMPLES = [Example(*match.groups()) for text in DOCS for match in MARKED.finditer(text)]


def expected_outputs(code: str) -> list[re.Pattern[str]]:
    """A pattern per ``print(...)  # output`` line, in order."""
    patterns = []
    for line in code.splitlines():
        if line.lstrip().startswith("print(") and "  # " in line:
            shown = line.split("  # ", 1)[1].strip()
            patterns.append(re.compile(re.escape(shown).replace(re.escape("..."), ".*")))
    return patterns


@pytest.fixture(scope="module")
def checkout(trained_models: dict[str, Model], tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A working directory laid out like the checkout after command (a), with a home whose
    demo models are the small trained ones."""
    if not (Path(sys.prefix) / "bin" / "lipstream").is_file():
        pytest.fail(f"no lipstream script in {sys.prefix}: run the tests with command (b)'s venv")
    work = tmp_path_factory.mktemp("readme")
    save_models(trained_models, work / "home" / "demo" / "models")
    (work / ".venv").symlink_to(Path(sys.prefix), target_is_directory=True)
    for name in ("examples", "client_sdk"):
        (work / name).symlink_to(REPO / name, target_is_directory=True)
    return work


@pytest.fixture(scope="module")
def server(checkout: Path) -> Iterator[LiveServer]:
    with live_server(checkout / "home" / "demo" / "models") as served:
        yield served


def run(example: Example, checkout: Path, base: str | None) -> subprocess.CompletedProcess[str]:
    code = example.code if base is None else DEFAULT_SERVER.sub(base, example.code)
    command = (
        [sys.executable, "-c", code]
        if example.language == "python"
        else ["bash", "-euo", "pipefail", "-c", code]
    )
    environment = {**os.environ, "LIPSTREAM_HOME": str(checkout / "home")}
    environment.pop("LIPSTREAM_MODELS", None)
    return subprocess.run(
        command,
        cwd=checkout,
        env=environment,
        capture_output=True,
        text=True,
        timeout=RUN_LIMIT_S,
        check=False,
    )


def test_every_python_example_is_marked_to_run() -> None:
    assert len([m for m in FENCE.finditer(README) if m.group(1) == "python"]) == len(
        [example for example in EXAMPLES if example.language == "python"]
    )
    assert {(example.where, example.language) for example in EXAMPLES} == {
        ("offline", "python"),
        ("offline", "bash"),
        ("server", "python"),
        ("server", "bash"),
    }


def test_expected_output_patterns_match_only_what_they_show() -> None:
    (pattern,) = expected_outputs("print(x)  # (37, 28) ('jawOpen', ...) 60.0\n")
    assert pattern.fullmatch("(37, 28) ('jawOpen', 'mouthClose') 60.0")
    assert not pattern.fullmatch("(36, 28) ('jawOpen', 'mouthClose') 60.0")


@pytest.mark.parametrize(
    "example", [e for e in EXAMPLES if e.where == "offline"], ids=lambda e: e.label
)
def test_offline_example_runs(example: Example, checkout: Path) -> None:
    shutil.rmtree(checkout / OUT, ignore_errors=True)
    before = set(checkout.iterdir())
    result = run(example, checkout, None)
    assert result.returncode == 0, result.stderr
    printed = result.stdout.splitlines()
    patterns = expected_outputs(example.code)
    assert len(printed) >= len(patterns)
    for pattern, line in zip(patterns, printed):
        assert pattern.fullmatch(line), (pattern.pattern, line)
    # an example writes into a folder of its own, never beside the checkout's files
    assert set(checkout.iterdir()) - before <= {checkout / OUT}
    if f"--out {OUT}/hello.csv" in example.code:
        rows = (checkout / OUT / "hello.csv").read_text().splitlines()
        assert rows[0].startswith("time,") and len(rows) == 1 + 43  # 0.7 s at 60 fps
        assert (checkout / OUT / "hello.tsv").read_text().strip()
        assert (checkout / OUT / "there.wav").read_bytes()[:4] == b"RIFF"


@pytest.mark.parametrize(
    "example", [e for e in EXAMPLES if e.where == "server"], ids=lambda e: e.label
)
def test_server_example_runs(example: Example, checkout: Path, server: LiveServer) -> None:
    if "curl" in example.code and shutil.which("curl") is None:
        pytest.fail("curl is missing; the README's examples use it")
    base = server.http.removeprefix("http://")
    result = run(example, checkout, base)
    assert result.returncode == 0, result.stderr
    if "text/csv" in example.code:
        rows = result.stdout.splitlines()
        assert rows[0] == "time,A,B,C,D,E,F,G,H,X" and len(rows) == 1 + 11  # 0.35 s at 30 fps
    elif "curl" in example.code:
        body = json.loads(result.stdout)
        assert body["fps"] == 30 and body["channels"][:2] == ["viseme_sil", "viseme_PP"]
        assert body["stats"]["frames"] == 11  # 0.35 s at 30 fps
    elif "lipstream.v1.json" in example.code:
        printed = result.stdout.splitlines()
        assert printed[0] == "ready 0" and printed[-1] == "done 11", printed  # 0.35 s at 30 fps
        blocks = [line.split() for line in printed[1:-1]]
        assert blocks and all(kind == "frames" for kind, _ in blocks)
        assert sum(int(count) for _, count in blocks) == 11
    elif "game_loop.py" in example.code:
        assert re.search(r"done: end, \d+ frames", result.stdout), result.stdout
    else:
        assert result.stdout.startswith("('jawOpen', 'mouthClose', "), result.stdout
