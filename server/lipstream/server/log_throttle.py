"""A logging filter that lets a line repeated in a flood through a few times, then counts it.

Sketch: a failure that repeats on every turn of the event loop (``accept`` failing with
"Too many open files", a client error storm) would otherwise write one line per turn: tens of
thousands a second, filling disks and hiding everything else. ``LogThrottle`` keys each record
by logger, level and formatted message. In each ``period_s`` the first ``burst`` records of a
key pass; the rest are dropped and counted, and the first record of the key after the period
ends passes carrying the count (``[N more like this in the last P s]``), which opens a new
period. Keys are kept in arrival order and the oldest are forgotten beyond ``max_keys``, so
lines that never repeat cost a bounded amount of memory. ``install`` attaches one throttle to
the loggers the server's floods come from (a logger's filters see only records logged to
that very logger, so each is named).
"""

from __future__ import annotations

import logging
import time
from collections import OrderedDict
from collections.abc import Callable, Iterable
from dataclasses import dataclass

THROTTLED_LOGGERS = ("asyncio", "uvicorn.error", "lipstream.server")
BURST = 5
PERIOD_S = 10.0
MAX_KEYS = 1024

_Key = tuple[str, int, str]


@dataclass
class _Window:
    started: float
    passed: int = 0
    dropped: int = 0


class LogThrottle(logging.Filter):
    """Passes ``burst`` identical records per ``period_s``, then one with the count dropped."""

    def __init__(
        self,
        burst: int = BURST,
        period_s: float = PERIOD_S,
        max_keys: int = MAX_KEYS,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        super().__init__()
        self.burst = burst
        self.period_s = period_s
        self.max_keys = max_keys
        self.clock = clock
        self.windows: OrderedDict[_Key, _Window] = OrderedDict()

    def filter(self, record: logging.LogRecord) -> bool:
        key = (record.name, record.levelno, record.getMessage())
        now = self.clock()
        window = self.windows.get(key)
        if window is None or now - window.started >= self.period_s:
            dropped = window.dropped if window is not None else 0
            self._open(key, now)
            if dropped:
                record.msg = f"{record.getMessage()} [{dropped} more like this in the last "
                record.msg += f"{self.period_s:g} s]"
                record.args = None
            return True
        if window.passed < self.burst:
            window.passed += 1
            return True
        window.dropped += 1
        return False

    def _open(self, key: _Key, now: float) -> None:
        self.windows[key] = _Window(now, passed=1)
        self.windows.move_to_end(key)
        while len(self.windows) > self.max_keys:
            self.windows.popitem(last=False)


def install(names: Iterable[str] = THROTTLED_LOGGERS) -> LogThrottle:
    """Attach one throttle to each named logger (once: a logger that has one keeps it)."""
    throttle = LogThrottle()
    for name in names:
        logger = logging.getLogger(name)
        if not any(isinstance(existing, LogThrottle) for existing in logger.filters):
            logger.addFilter(throttle)
    return throttle
