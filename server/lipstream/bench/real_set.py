"""The real-face set the benches read, and the command-line arguments they share for it."""

from __future__ import annotations

import argparse
from pathlib import Path

REAL_SET = Path(__file__).resolve().parents[3] / "tests" / "data" / "grid" / "corpus"
"""The shipped GRID real-face corpus (``tests/data/grid``)."""


def real_set_parser(prog: str, doc: str | None, *, home: bool = False) -> argparse.ArgumentParser:
    """An argument parser for a bench that reads the real-face set: ``--real`` (default
    ``REAL_SET``) and, with ``home``, ``--home`` (a ``LIPSTREAM_HOME`` holding a demo build);
    described by the first line of ``doc``."""
    parser = argparse.ArgumentParser(prog=prog, description=(doc or "").splitlines()[0])
    if home:
        parser.add_argument("--home", type=Path, required=True, help="LIPSTREAM_HOME with a demo")
    parser.add_argument("--real", type=Path, default=REAL_SET, help="real-face corpus")
    return parser
