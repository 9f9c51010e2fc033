"""Status lines for the long steps of the command line and of a server's start-up.

Sketch: ``phase(what, report)`` is a context manager that reports ``what ...`` as
a step begins and ``what: done in 1.2 s`` as it ends, so a user watching a first
start sees which step the time goes to (generating the demo corpus, training each
engine, warming up and calibrating each model). ``report`` is where lines go:
stderr for the command line, the server's log at start-up; ``None`` is silent.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

Report = Callable[[str], None]


def to_stderr(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


@contextmanager
def phase(what: str, report: Report | None) -> Iterator[None]:
    """Report ``what`` before the block and its duration after it (nothing when it raises)."""
    if report is None:
        yield
        return
    report(f"{what} ...")
    started = time.perf_counter()
    yield
    report(f"{what}: done in {time.perf_counter() - started:.1f} s")
