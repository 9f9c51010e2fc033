"""``lipstream serve`` binds its port and prints its first line before the heavy imports:
the command line and the package import none of numpy, scipy, numba, FastAPI, uvicorn."""

from __future__ import annotations

import subprocess
import sys

HEAVY = ("numpy", "scipy", "numba", "fastapi", "uvicorn")
PROBE = (
    "import sys, lipstream, lipstream.cli, lipstream.status, lipstream.server.front_door; "
    f"print(','.join(name for name in {HEAVY!r} if name in sys.modules))"
)


def test_the_command_line_imports_nothing_heavy() -> None:
    result = subprocess.run(
        [sys.executable, "-c", PROBE], capture_output=True, text=True, timeout=120, check=True
    )
    assert result.stdout.strip() == ""


def test_the_public_names_still_load_on_first_use() -> None:
    import lipstream
    from lipstream.engines import load_model
    from lipstream.engines.base import Model
    from lipstream.timeline import PhonemeSpan

    assert lipstream.load_model is load_model
    assert lipstream.Model is Model and lipstream.PhonemeSpan is PhonemeSpan
    assert sorted(lipstream.__all__) == sorted(dir(lipstream))
    try:
        lipstream.no_such_name  # noqa: B018
    except AttributeError as error:
        assert "no_such_name" in str(error)
    else:
        raise AssertionError("an unknown name must raise AttributeError")
