"""Serving leaves the process as it found it: gc is frozen only by the serving process, once,
and the environment the workers need is set only while uvicorn runs."""

from __future__ import annotations

import asyncio
import gc
import os
from pathlib import Path
from typing import Any

import pytest
from fastapi import FastAPI

from lipstream.config import ServerSettings
from lipstream.server import app as app_module
from lipstream.server import runner
from lipstream.server.app import create_app


def _run_lifespan(app: FastAPI) -> None:
    async def start_and_stop() -> None:
        async with app.router.lifespan_context(app):
            pass

    asyncio.run(start_and_stop())


@pytest.fixture
def freezes(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Counts ``gc.freeze`` calls, as if this process had never frozen; the young
    generation's threshold the process sets goes to ``thresholds``."""
    calls: list[int] = []
    monkeypatch.setattr(app_module, "_frozen", False)
    monkeypatch.setattr(gc, "freeze", lambda: calls.append(1))
    thresholds.clear()
    monkeypatch.setattr(gc, "set_threshold", lambda young, *older: thresholds.append(young))
    return calls


thresholds: list[int] = []


def test_an_app_built_outside_serve_leaves_gc_and_the_environment_alone(
    lerp_dir: Path, freezes: list[int]
) -> None:
    environment = dict(os.environ)
    for _ in range(2):
        _run_lifespan(create_app(lerp_dir, ServerSettings()))
    assert freezes == [] and thresholds == []
    assert dict(os.environ) == environment


def test_the_serving_process_freezes_once_after_its_models_load(
    lerp_dir: Path, freezes: list[int]
) -> None:
    app = create_app(lerp_dir, ServerSettings(), serving_process=True)
    _run_lifespan(app)
    _run_lifespan(create_app(lerp_dir, ServerSettings(), serving_process=True))
    assert freezes == [1]
    assert thresholds == [20_000] and gc.get_threshold()[0] < 20_000  # this one untouched


def test_workers_get_the_settings_and_the_environment_is_restored(
    lerp_dir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    settings = ServerSettings(
        workers=2,
        max_sessions=7,
        idle_timeout_s=12.5,
        auth_tokens=("alpha", "beta"),
        allowed_origins=("https://example.org",),
        profiles=Path("/srv/profiles.json"),
    )
    seen: dict[str, Any] = {}

    def fake_supervise(host: str, port: int, server: ServerSettings, drain_flag: Path) -> None:
        described = os.environ.get(runner.WORKER_APP_ENV)
        seen.update(server=server, flag=drain_flag, described=described)
        assert drain_flag.parent.is_dir() and not drain_flag.exists()

    monkeypatch.setattr(runner, "supervise", fake_supervise)
    monkeypatch.setenv(runner.WORKER_APP_ENV, "left by someone else")
    monkeypatch.delenv("LIPSTREAM_MODELS", raising=False)
    environment = dict(os.environ)
    runner.serve(lerp_dir, "127.0.0.1", 0, settings)
    assert dict(os.environ) == environment
    assert seen["server"] == settings
    assert runner.decode_worker_app(seen["described"]) == (lerp_dir, settings)
    assert runner.worker_drain_flag(seen["described"]) == seen["flag"]
    assert not seen["flag"].parent.exists()  # the private directory is gone with the server

    built: dict[str, Any] = {}
    monkeypatch.setattr(
        runner,
        "create_app",
        lambda models, server, **flags: built.update(models=models, server=server, **flags),
    )
    monkeypatch.setenv(runner.WORKER_APP_ENV, seen["described"])
    runner.app_from_environment()
    assert built == {
        "models": lerp_dir,
        "server": settings,
        "serving_process": True,
        "drain_flag": seen["flag"],
    }


def test_a_worker_without_a_description_reads_the_lipstream_environment(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    built: dict[str, Any] = {}
    monkeypatch.setattr(
        runner,
        "create_app",
        lambda models, server, **flags: built.update(models=models, server=server, **flags),
    )
    monkeypatch.delenv(runner.WORKER_APP_ENV, raising=False)
    monkeypatch.setenv("LIPSTREAM_MODELS", str(tmp_path))
    monkeypatch.setenv("LIPSTREAM_MAX_SESSIONS", "3")
    runner.app_from_environment()
    assert built["models"] == tmp_path and built["server"].max_sessions == 3
    assert built["serving_process"] is True
