"""The open-file limit, raised in subprocesses (and ``lipstream serve``) started with a low
soft limit."""

from __future__ import annotations

import json
import resource
import subprocess
import sys
from pathlib import Path

import httpx

from lipstream.server.open_files import FILE_RESERVE, OpenFileLimit, connection_cap
from tests.helpers import eventually, free_port
from tests.live_server import READY_POLLS, stop_process

RAISE = """
import json, resource
from lipstream.server.open_files import raise_open_file_limit
before = resource.getrlimit(resource.RLIMIT_NOFILE)
reported = raise_open_file_limit(target=TARGET)
after = resource.getrlimit(resource.RLIMIT_NOFILE)
print(json.dumps({"before": before, "after": after, "reported": [reported.soft, reported.hard]}))
"""


def limits_after_raise(soft: int, target: int) -> dict[str, list[int]]:
    _, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    result = subprocess.run(
        [sys.executable, "-c", RAISE.replace("TARGET", str(target))],
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
        preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard)),
    )
    limits: dict[str, list[int]] = json.loads(result.stdout)
    return limits


def test_the_soft_limit_rises_to_the_hard_limit_or_the_target() -> None:
    _, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    assert hard >= 512, "the test needs a hard limit of at least 512"
    limits = limits_after_raise(soft=256, target=1 << 20)
    expected = hard if hard == resource.RLIM_INFINITY else min(hard, 1 << 20)
    assert limits["before"] == [256, hard]
    assert limits["after"] == [expected, hard] == limits["reported"]
    lower = limits_after_raise(soft=256, target=300)
    assert lower["after"] == [300, hard]


def test_a_soft_limit_above_the_target_is_left_alone() -> None:
    _, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    limits = limits_after_raise(soft=400, target=300)
    assert limits["after"] == [400, hard]


def test_the_connection_cap_leaves_descriptors_free() -> None:
    assert FILE_RESERVE == 128
    assert connection_cap(4096, OpenFileLimit(1024, 1024)) == 896
    assert connection_cap(500, OpenFileLimit(1024, 4096)) == 500
    assert connection_cap(4096, OpenFileLimit(100, 100)) == 1
    assert connection_cap(4096, OpenFileLimit(resource.RLIM_INFINITY, -1)) == 4096


def test_lipstream_serve_raises_its_limit_at_start(lerp_dir: Path) -> None:
    _, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    expected = hard if hard == resource.RLIM_INFINITY else min(hard, 1 << 20)
    port = free_port()
    process = subprocess.Popen(
        [sys.executable, "-m", "lipstream.cli", "serve", "--models", str(lerp_dir)]
        + ["--host", "127.0.0.1", "--port", str(port), "--log-level", "warning"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_NOFILE, (256, hard)),
    )
    try:
        eventually(
            lambda: process.poll() is not None or _answers(f"http://127.0.0.1:{port}/healthz"),
            "lipstream serve answered or exited",
            READY_POLLS,
        )
        assert process.poll() is None, "lipstream serve exited"
        limits = Path(f"/proc/{process.pid}/limits").read_text()
        [row] = [line for line in limits.splitlines() if line.startswith("Max open files")]
        soft = row.split()[3]
        assert soft == ("unlimited" if expected == resource.RLIM_INFINITY else str(expected))
    finally:
        stop_process(process)


def _answers(url: str) -> bool:
    try:
        return httpx.get(url, timeout=1.0).status_code == 200
    except httpx.TransportError:
        return False
