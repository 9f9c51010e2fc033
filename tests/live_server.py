"""``lipstream serve`` as a real uvicorn process on loopback, for end-to-end tests."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import tempfile
import urllib.error
import urllib.request
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, AnyStr

import httpx
from prometheus_client.multiprocess import MultiProcessCollector

from tests.helpers import EVENTUALLY_PAUSE_S, eventually, free_port, serve_command

if TYPE_CHECKING:
    from lipstream.engines.base import Model

READY_POLLS = round(120.0 / EVENTUALLY_PAUSE_S)  # a bound on a busy machine, not a speed claim


@dataclass(frozen=True)
class LiveServer:
    http: str
    models_dir: Path
    pid: int | None = None

    @property
    def ws(self) -> str:
        return self.http.replace("http://", "ws://", 1) + "/v1/stream"


def save_models(models: Mapping[str, Model], directory: Path) -> Path:
    """Save each model under ``directory/<engine>`` and return ``directory``."""
    for name, model in models.items():
        model.save(directory / name)
    return directory


def _ready(base: str) -> bool:
    opener = urllib.request.build_opener(urllib.request.ProxyHandler({}))
    try:
        with opener.open(f"{base}/readyz", timeout=1.0) as answer:
            return bool(answer.status == 200)
    except (OSError, urllib.error.HTTPError):
        return False


@contextmanager
def live_server(models_dir: Path, *extra: str) -> Iterator[LiveServer]:
    """Serve ``models_dir`` on a free loopback port until the block ends."""
    port = free_port()
    # A file, not a pipe: nobody reads the log while the server runs, and a full
    # pipe would block it.
    with tempfile.TemporaryFile(mode="w+") as log:
        process = subprocess.Popen(
            serve_command(models_dir, port, *extra),
            stdout=log,
            stderr=subprocess.STDOUT,
            text=True,
        )
        base = f"http://127.0.0.1:{port}"
        try:
            eventually(
                lambda: process.poll() is not None or _ready(base),
                "lipstream serve ready",
                READY_POLLS,
            )
            if process.poll() is not None:
                log.seek(0)
                raise RuntimeError(f"lipstream serve exited: {log.read()[-2000:]}")
            yield LiveServer(base, models_dir, process.pid)
        finally:
            stop_process(process)


def stop_process(process: subprocess.Popen[AnyStr]) -> None:
    """SIGTERM, then SIGKILL if the process has not exited within 15 s; then SIGKILL to any
    of its descendants still running (workers of a supervisor that was killed, or failed to
    stop them), so no server outlives its test."""
    descendants = _descendants(process.pid)
    if process.poll() is None:
        process.terminate()
    try:
        process.wait(timeout=15)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait(timeout=5)
    for pid in descendants + _descendants(process.pid):
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)


def _descendants(pid: int) -> list[int]:
    """Every live descendant of ``pid`` (from /proc), children before their children."""
    found: list[int] = []
    for task in Path(f"/proc/{pid}/task").glob("*"):
        with contextlib.suppress(OSError):
            for child in (task / "children").read_text().split():
                found += [int(child), *_descendants(int(child))]
    return found


@contextmanager
def lipstream_serve(
    models: Path, workers: int, environ: dict[str, str], log: Path
) -> Iterator[tuple[subprocess.Popen[bytes], str]]:
    """``lipstream serve`` on a free loopback port, every worker started, its output in
    ``log``; SIGTERM (then SIGKILL) at the end."""
    port = free_port()
    env = {**os.environ, "LIPSTREAM_LOG_LEVEL": "info", "LIPSTREAM_DRAIN_TIMEOUT_S": "5", **environ}
    with log.open("ab") as output:
        process = subprocess.Popen(
            serve_command(models, port, "--workers", str(workers)),
            env=env,
            stdout=output,
            stderr=subprocess.STDOUT,
        )
    base = f"http://127.0.0.1:{port}"
    try:
        # /readyz answers once one worker is ready; each logs its own startup.
        eventually(
            lambda: process.poll() is not None or started(log) == workers,
            "every worker started",
            READY_POLLS,
        )
        if process.poll() is not None or not ready(base):
            raise RuntimeError(f"lipstream serve did not start: {log.read_text()[-2000:]}")
        yield process, base
    finally:
        stop_process(process)


def started(log: Path) -> int:
    """Workers that finished their startup (models loaded), from uvicorn's log."""
    return log.read_text(errors="replace").count("Application startup complete.")


def ready(base: str) -> bool:
    try:
        return httpx.get(f"{base}/readyz", timeout=1).status_code == 200
    except httpx.TransportError:
        return False


def per_worker(directory: Path, kind: str, name: str, **labels: str) -> dict[int, float]:
    """Sample ``name`` from each worker's own value file (``<kind>_<pid>.db``), by pid."""
    values = {}
    for path in directory.glob(f"{kind}_*.db"):
        pid = int(path.stem.rsplit("_", 1)[1])
        # prometheus_client leaves merge unannotated, as lipstream.server.metrics notes too
        merged = MultiProcessCollector.merge([str(path)], accumulate=True)  # type: ignore[no-untyped-call]
        values[pid] = sum(
            sample.value
            for metric in merged
            for sample in metric.samples
            if sample.name == name and sample.labels == labels
        )
    return values


def sessions_by_worker(directory: Path) -> dict[int, float]:
    return per_worker(directory, "gauge_livesum", "lipstream_sessions")
