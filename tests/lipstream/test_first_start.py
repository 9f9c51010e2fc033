"""README command (a)'s path: ``lipstream serve`` with no models builds the demo, then serves.

The demo corpus is written beforehand from the suite's small one (24 sentences), as
``build_demo`` leaves an existing corpus in place: generating the full corpus has its own
tests (tests/lipstream/demo), and training six engines on all of it took two of CI's
twenty minutes. The path under test, no models → train every engine → serve, is the same.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import httpx

from lipstream.corpus import Corpus
from lipstream.corpus.writer import write_corpus
from lipstream.engines import engine_names
from tests.helpers import eventually, free_port

BUILD_POLLS = 1200  # half a second apart: a bound for a loaded machine, not a speed


def test_first_start_builds_the_demo_then_serves_every_engine(
    tmp_path: Path, small_demo_corpus: Corpus
) -> None:
    write_corpus(small_demo_corpus, tmp_path / "home" / "demo" / "corpus")
    port = free_port()
    environment = {**os.environ, "LIPSTREAM_HOME": str(tmp_path / "home")}
    environment.pop("LIPSTREAM_MODELS", None)
    log = tmp_path / "serve.log"
    process = subprocess.Popen(
        [sys.executable, "-m", "lipstream.cli", "serve", "--port", str(port)],
        env=environment,
        stdout=subprocess.DEVNULL,
        stderr=log.open("w"),
    )
    base = f"http://127.0.0.1:{port}"
    try:
        phases: dict[str, str] = {}  # each phase /readyz named before ready: its first status
        healthy_while_building = False

        def built() -> bool:
            nonlocal healthy_while_building
            if process.poll() is not None:
                return True
            try:
                answer = httpx.get(f"{base}/readyz", timeout=1.0)
                if answer.status_code == 200:
                    return True
                phases.setdefault(answer.json()["phase"], answer.json()["status"])
                if answer.json()["phase"] == "building" and not healthy_while_building:
                    healthy_while_building = httpx.get(f"{base}/healthz").status_code == 200
            except httpx.TransportError:
                pass
            return False

        eventually(built, "the demo is built and served", polls=BUILD_POLLS, pause_s=0.5)
        assert process.poll() is None, log.read_text()[-2000:]
        assert httpx.get(f"{base}/readyz").json() == {
            "ready": True,
            "phase": "ready",
            "failed_models": [],
        }
        # training six engines takes far longer than a probe's half second
        assert "building" in phases and healthy_while_building
        assert set(phases) <= {"starting", "building", "loading", "calibrating"}
        assert httpx.get(f"{base}/healthz").json() == {"status": "ok"}
        characters = httpx.get(f"{base}/v1/characters").json()["characters"]
        assert characters == [{"name": "demo", "engines": sorted(engine_names())}]
    finally:
        process.terminate()
        process.wait(timeout=30)
    output = log.read_text()
    for engine in engine_names():
        assert f"training {engine} and compiling its kernels: done in " in output
    assert "ready in " in output
    models = tmp_path / "home" / "demo" / "models"
    assert sorted(p.name for p in models.iterdir()) == sorted(engine_names())
    assert (tmp_path / "home" / "demo" / "corpus" / "corpus.json").is_file()
