"""``lipstream serve`` as a subprocess for the scale-out benchmarks: started, ready, stopped.

Method: the server runs on a free loopback port with its log in a temporary
file; it is ready once every worker has logged uvicorn's start-up line
(models loaded, warmed up and calibrated) and ``/readyz`` answers 200. At
the end it gets SIGTERM (it drains) and, if it has not exited within a
minute, SIGKILL. ``children`` lists a process's children from /proc (Linux).
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import IO

START_TIMEOUT_S = 600.0
STARTED = "Application startup complete."


@dataclass(frozen=True)
class Served:
    """A running server: its process, port and log."""

    process: subprocess.Popen[bytes]
    port: int
    log: IO[str]

    def workers_started(self) -> int:
        """How many workers have completed their start-up so far (replacements too)."""
        self.log.seek(0)
        return self.log.read().count(STARTED)

    @property
    def ws(self) -> str:
        return f"ws://127.0.0.1:{self.port}/v1/stream"


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port: int = probe.getsockname()[1]
        return port


def ready(port: int) -> bool:
    try:
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/readyz", timeout=2) as answer:
            return bool(answer.status == 200)
    except OSError:
        return False


def children(pid: int) -> list[int]:
    found: list[int] = []
    for task in Path(f"/proc/{pid}/task").glob("*"):
        found += [int(child) for child in (task / "children").read_text().split()]
    return found


@contextmanager
def serving(models: Path, workers: int, environ: Mapping[str, str] = {}) -> Iterator[Served]:
    """``lipstream serve --models models --workers workers`` until the block ends."""
    port = free_port()
    command = [sys.executable, "-m", "lipstream.cli", "serve", "--models", str(models)]
    command += ["--host", "127.0.0.1", "--port", str(port), "--workers", str(workers)]
    with tempfile.TemporaryFile("w+") as log:
        env = {**os.environ, "LIPSTREAM_LOG_LEVEL": "info", **environ}
        process = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT, env=env)
        try:
            deadline = time.monotonic() + START_TIMEOUT_S
            while True:
                log.seek(0)
                if log.read().count(STARTED) >= workers and ready(port):
                    break
                if process.poll() is not None or time.monotonic() > deadline:
                    log.seek(0)
                    raise RuntimeError(f"the server did not start: {log.read()[-2000:]}")
                time.sleep(0.5)
            yield Served(process, port, log)
        finally:
            process.send_signal(signal.SIGTERM)
            try:
                process.wait(timeout=60)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
