"""Capture is an extra: the server never imports it, the command line builds its parser
without PyAV or mediapipe, and without them ``lipstream capture`` says what to install."""

from __future__ import annotations

import subprocess
import sys

from tests.lipstream.capture.clips import CLIP


def run_python(code: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=False
    )


def test_the_server_and_the_command_line_import_no_capture_package() -> None:
    probe = (
        "import sys, lipstream.cli, lipstream.server.app; "
        "print(sorted(m for m in ('av', 'mediapipe', 'lipstream.capture.pipeline', "
        "'lipstream.capture.track', 'lipstream.frontends.align', 'pocketsphinx') "
        "if m in sys.modules))"
    )
    result = run_python(probe)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "[]"


def test_without_the_extra_capture_names_it(tmp_path: object) -> None:
    code = (
        "import sys; sys.modules['av'] = None; sys.modules['mediapipe'] = None; "
        "from lipstream.cli import main; "
        f"sys.exit(main(['capture', {str(CLIP)!r}, '--transcript', 'set white', "
        f"'--out', {str(tmp_path)!r} + '/c']))"
    )
    result = run_python(code)
    assert result.returncode == 2
    assert result.stderr.startswith("error [missing_dependency]: av: lipstream capture needs")
    assert 'pip install "lipstream[capture]"' in result.stderr
