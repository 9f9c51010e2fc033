"""Where the measuring commands (``bench``, ``loadtest`` and its ``soak``, ``storm`` and
``capacity``, the ``lipstream.bench`` scripts) put their results: one JSON document per
file, indented, ending in a newline, its directory made first, opening with what made it
(``recorded``: command, version, date, machine) so that ``python -m lipstream.bench.report``
can say where each figure comes from. Imports nothing of the server, so both the load tests
and the benches use it."""

from __future__ import annotations

import json
import os
import platform
import shlex
import sys
from collections.abc import Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from ._version import __version__
from .errors import LipstreamError


def write_results(results: dict[str, Any], path: Path) -> None:
    """Write ``results`` to ``path`` as indented JSON, replacing the file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(results, indent=2) + "\n", encoding="utf-8")


def read_accumulated(path: Path, runs: str, kind: str) -> dict[str, Any]:
    """A results file that gathers a command's runs under the list ``runs`` (an empty one
    when there is none yet); LipstreamError ``invalid_results_file`` when it cannot be read
    or is not a ``kind`` results file, which the command must not overwrite."""
    if not path.exists():
        return {runs: []}
    try:
        document = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as error:
        raise LipstreamError(
            f"cannot read the results file: {error}", where=str(path), code="invalid_results_file"
        ) from None
    if not isinstance(document, dict) or not isinstance(document.get(runs), list):
        raise LipstreamError(
            f"the file is not a {kind} results file (no '{runs}' list); choose another "
            "--results rather than overwrite it",
            where=str(path),
            code="invalid_results_file",
        )
    return document


def recorded(command: str) -> dict[str, Any]:
    """What a results file opens with: the ``command`` that made it, lipstream's version,
    the date (UTC) and the machine."""
    return {
        "command": command,
        "lipstream_version": __version__,
        "date": datetime.now(UTC).isoformat(timespec="seconds"),
        "machine": machine(),
    }


def script_command(module: str, argv: Sequence[str] | None) -> str:
    """The command line of ``python -m module`` run with ``argv`` (default: this process's)."""
    given = list(argv) if argv is not None else sys.argv[1:]
    return shlex.join(["python", "-m", module, *given])


def machine() -> dict[str, Any]:
    """The cores this process may run on, the processor's model, the system and Python."""
    model = ""
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.is_file():
        for line in cpuinfo.read_text(encoding="utf-8").splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return {
        "cores": cores,
        "processor": model or platform.machine(),
        "system": platform.system(),
        "python": platform.python_version(),
    }
