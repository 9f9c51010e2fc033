"""Status lines for the long steps of the command line and of a server's start-up.

Sketch: ``phase(what, report)`` is a context manager that reports ``what ...`` as
a step begins and ``what: done in 1.2 s`` as it ends, so a user watching a first
start sees which step the time goes to (generating the demo corpus, training each
engine, warming up and calibrating each model). ``report`` is where lines go:
stderr for the command line, the server's log at start-up; ``None`` is silent.
A step can run for tens of seconds without a line of its own (one engine's
training, one stage of a progress bar), so a ``Heartbeat`` wraps the report: it
notes when it last wrote a line and, whenever ``interval_s`` passes without one
while a step is under way, repeats the step with its elapsed time
(``training dam ...: 12 s``). Its clock is injected, and ``beat`` is the single
check its thread repeats, so it is tested without waiting.
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

Report = Callable[[str], None]
Clock = Callable[[], float]

HEARTBEAT_S = 1.5  # under the 2 s a user should ever wait for a line, with room for a busy machine
BEGUN = " ..."
DONE = ": done in "


def to_stderr(line: str) -> None:
    """Print ``line`` on stderr, above any progress bar drawn there (tqdm redraws it below)."""
    from tqdm import tqdm

    tqdm.write(line, file=sys.stderr)
    sys.stderr.flush()


@contextmanager
def phase(what: str, report: Report | None) -> Iterator[None]:
    """Report ``what`` before the block and its duration after it (nothing when it raises)."""
    if report is None:
        yield
        return
    report(f"{what}{BEGUN}")
    started = time.perf_counter()
    yield
    report(f"{what}{DONE}{time.perf_counter() - started:.1f} s")


class Heartbeat:
    """A report that repeats the step under way whenever ``interval_s`` passes silently.

    ``report`` passes a line on and follows the steps ``phase`` opens (``what ...``) and
    closes (``what: done in``); ``beat`` reports each open step as ``what ...: N s`` when
    the last output is ``interval_s`` old. ``start`` runs ``beat`` on a daemon thread,
    waking when the last line turns ``interval_s`` old, until ``stop``."""

    def __init__(
        self, report: Report, interval_s: float = HEARTBEAT_S, clock: Clock = time.monotonic
    ) -> None:
        self.interval_s = interval_s
        self._report = report
        self._clock = clock
        self._lock = threading.Lock()
        self._steps: list[tuple[str, float]] = []
        self._last_output = clock()
        self._stopped = threading.Event()
        self._thread: threading.Thread | None = None

    def report(self, line: str) -> None:
        now = self._clock()
        with self._lock:
            if line.endswith(BEGUN):
                self._steps.append((line[: -len(BEGUN)], now))
            elif DONE in line:
                finished = line.split(DONE, 1)[0]
                self._steps = [step for step in self._steps if step[0] != finished]
            self._last_output = now
        self._report(line)

    def beat(self) -> bool:
        """Report the open steps when output has been silent for ``interval_s``."""
        now = self._clock()
        with self._lock:
            if not self._steps or now - self._last_output < self.interval_s:
                return False
            steps = list(self._steps)
            self._last_output = now
        self._report("; ".join(f"{what}{BEGUN}: {int(now - began)} s" for what, began in steps))
        return True

    def until_due(self) -> float:
        """Seconds until ``beat`` may next report: when the last line turns ``interval_s``
        old, or, with no step open, an interval from now (a step opened meanwhile is due
        no sooner than that)."""
        now = self._clock()
        with self._lock:
            since = self._last_output if self._steps else now
        return max(0.0, since + self.interval_s - now)

    def start(self) -> Heartbeat:
        def run() -> None:
            while not self._stopped.wait(self.until_due()):
                self.beat()

        self._thread = threading.Thread(target=run, name="lipstream-heartbeat", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stopped.set()
        if self._thread is not None:
            self._thread.join()
