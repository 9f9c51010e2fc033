"""``lipstream serve`` as a real uvicorn process on loopback."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from lipstream.corpus import Corpus
from lipstream.training import train_engine
from tests.helpers import eventually, free_port, serve_command
from tests.live_server import READY_POLLS


def readyz(base: str) -> int:
    try:
        return httpx.get(f"{base}/readyz", timeout=1.0).status_code
    except httpx.TransportError:
        return 0


@pytest.fixture(scope="module")
def served(small_demo_corpus: Corpus, tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    models = tmp_path_factory.mktemp("models")
    train_engine(small_demo_corpus, "viseme-lerp", models / "viseme-lerp")
    port = free_port()
    process = subprocess.Popen(
        serve_command(models, port),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    base = f"http://127.0.0.1:{port}"
    try:
        eventually(lambda: readyz(base) == 200, "lipstream serve ready", READY_POLLS)
        yield base
    finally:
        process.terminate()
        process.wait(timeout=10)


def test_health_and_readiness(served: str) -> None:
    assert httpx.get(f"{served}/healthz").json() == {"status": "ok"}
    assert httpx.get(f"{served}/readyz").json() == {
        "ready": True,
        "phase": "ready",
        "failed_models": [],
    }


def test_lists_loaded_engines_and_characters(served: str) -> None:
    engines = {e["name"]: e["loaded"] for e in httpx.get(f"{served}/v1/engines").json()["engines"]}
    assert engines["viseme-lerp"] is True
    characters = httpx.get(f"{served}/v1/characters").json()["characters"]
    assert characters == [{"name": "demo", "engines": ["viseme-lerp"]}]


def test_serving_a_missing_directory_fails_with_one_line(tmp_path: Path) -> None:
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "lipstream.cli",
            "serve",
            "--models",
            str(tmp_path / "none"),
            "--port",
            str(free_port()),
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode != 0
    assert "no such directory" in result.stderr
