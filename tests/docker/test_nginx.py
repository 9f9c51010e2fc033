"""docker/nginx/lipstream.conf: Debian's nginx accepts it, and its timeouts outlast an utterance.

``nginx -t`` parses the whole file and checks every directive, with a
private prefix, error log and pid file so that it needs no root and touches
nothing outside the test's directory. A copy with one directive broken must
fail the same check (the check can fail). The WebSocket location must
upgrade, and its timeouts, like nginx's own drain on reload, must outlast
the longest utterance and the drain the recipe names.
"""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

from tests.helpers import REPO

CONF = REPO / "docker" / "nginx" / "lipstream.conf"
LONGEST_UTTERANCE_S = 120  # the recipe's LIPSTREAM_MAX_REQUEST_S
DRAIN_TIMEOUT_S = 150  # the recipe's LIPSTREAM_DRAIN_TIMEOUT_S


def nginx() -> str:
    found = shutil.which("nginx") or next(
        (path for path in ("/usr/sbin/nginx",) if Path(path).exists()), None
    )
    if found is None:
        pytest.skip("Debian's nginx is not installed (README command (b) apt-installs it)")
    return found


def check(conf: Path, prefix: Path) -> subprocess.CompletedProcess[str]:
    (prefix / "logs").mkdir(parents=True, exist_ok=True)
    return subprocess.run(
        [
            nginx(),
            "-t",
            "-q",
            "-c",
            str(conf),
            "-p",
            str(prefix),
            "-e",
            str(prefix / "logs" / "error.log"),
            "-g",
            f"pid {prefix / 'nginx.pid'};",
        ],
        capture_output=True,
        text=True,
        timeout=30,
    )


def test_nginx_accepts_the_recipe_and_refuses_a_broken_copy(tmp_path: Path) -> None:
    result = check(CONF, tmp_path / "good")
    assert result.returncode == 0, result.stderr
    broken = tmp_path / "broken.conf"
    broken.write_text(CONF.read_text().replace("proxy_read_timeout 300s;", "proxy_read_timeout;"))
    refused = check(broken, tmp_path / "bad")
    assert refused.returncode != 0
    assert "proxy_read_timeout" in refused.stderr


def seconds(directive: str, text: str) -> list[int]:
    return [int(value) for value in re.findall(rf"^\s*{directive} (\d+)s;", text, re.MULTILINE)]


def test_the_stream_upgrades_and_outlasts_the_longest_utterance_and_the_drain() -> None:
    text = CONF.read_text()
    stream = re.search(r"location = /v1/stream \{(.*?)\}", text, re.DOTALL)
    assert stream is not None
    block = stream.group(1)
    assert "proxy_http_version 1.1;" in block
    assert "proxy_set_header Upgrade $http_upgrade;" in block
    assert "proxy_set_header Connection $connection_upgrade;" in block
    assert "proxy_buffering off;" in block
    for directive in ("proxy_read_timeout", "proxy_send_timeout"):
        [value] = seconds(directive, block)
        assert value > DRAIN_TIMEOUT_S > LONGEST_UTTERANCE_S
    [shutdown] = seconds("worker_shutdown_timeout", text)
    assert shutdown > DRAIN_TIMEOUT_S
    assert f"LIPSTREAM_MAX_REQUEST_S={LONGEST_UTTERANCE_S}" in text
    assert f"LIPSTREAM_DRAIN_TIMEOUT_S={DRAIN_TIMEOUT_S}" in text
