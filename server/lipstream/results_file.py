"""Where the measuring commands (``bench``, ``loadtest`` and its ``soak``, ``storm`` and
``capacity``) put their results: one JSON document per file, indented, ending in a newline,
its directory made first. Imports nothing of the server, so both the load tests and the
benches use it."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any


def write_results(results: dict[str, Any], path: Path) -> None:
    """Write ``results`` to ``path`` as indented JSON, replacing the file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(results, indent=2) + "\n", encoding="utf-8")
