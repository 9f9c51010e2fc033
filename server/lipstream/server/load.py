"""How loaded this process is: event-loop lag, the loop's CPU, resident memory, sampled on a timer.

Sketch: a ``LoadMonitor`` runs a timer callback every ``interval_s`` on the event loop it
watches. Each tick records how late it ran (the loop's *lag*: how long every callback then
waits behind the others), the CPU time the loop's thread has used (``time.thread_time``
inside the callback, so only the loop's thread counts: the synthesis pool's threads do not
delay the loop's callbacks) and the resident set size (``/proc/self/statm`` on Linux, else the
peak ``ru_maxrss``). ``sample`` summarises the last ``window_s``: the median lag (one stall
of another thread holding the GIL does not count; a saturated loop lags on every tick), or
more if the next tick is overdue already (a long batch of callbacks, say a burst of
handshakes admitted one after another, holds the ticks back while it runs), the loop's busy
fraction of one core over the window (at least a whole window, so the first moments after
start do not count as busy all the time), the receive lag (the median over the window's
ticks of the longest wait, within each tick, of a client message between the socket's bytes
reaching the process and the app taking it: ``observe_receive``, fed by the WebSocket
transport, ``read_window``), and the latest RSS. ``machine_memory_mb``
is the memory this process may use: the physical memory, or a smaller cgroup limit
(a container's).
"""

from __future__ import annotations

import asyncio
import os
import resource
import statistics
import sys
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

INTERVAL_S = 0.1
WINDOW_S = 1.0
MIB = 1 << 20
CGROUP_LIMITS = (
    Path("/sys/fs/cgroup/memory.max"),
    Path("/sys/fs/cgroup/memory/memory.limit_in_bytes"),
)


@dataclass(frozen=True)
class LoadSample:
    """The median event-loop lag (ms) and the loop's busy fraction of one core over the last
    window, the resident memory (MiB) now, and the receive lag (ms) over the window."""

    lag_ms: float = 0.0
    loop_busy: float = 0.0
    rss_mb: float = 0.0
    receive_lag_ms: float = 0.0


@dataclass(frozen=True)
class _Tick:
    wall: float
    cpu: float
    lag_s: float
    receive_lag_s: float = 0.0


@dataclass(frozen=True)
class _Window:
    ticks: deque[_Tick]
    last: _Tick
    busy: float
    lag_s: float
    receive_lag_s: float


class LoadMonitor:
    """Samples the event loop it is started on, every ``interval_s``."""

    def __init__(
        self,
        interval_s: float = INTERVAL_S,
        window_s: float = WINDOW_S,
        on_sample: Callable[[LoadSample], None] | None = None,
    ) -> None:
        """``on_sample`` gets the new sample after every tick (to publish it as metrics)."""
        self.interval_s = interval_s
        self.window_s = window_s
        self.on_sample = on_sample
        self.ticks: deque[_Tick] = deque(maxlen=max(2, round(window_s / interval_s) + 1))
        self.rss_mb = resident_mb()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: int | None = None
        self._timer: asyncio.TimerHandle | None = None
        self._due = 0.0
        self._receive_lag_s = 0.0
        self._window: _Window | None = None
        self.last_tick_s = time.monotonic()

    def start(self) -> None:
        """Start sampling the running loop."""
        self._loop = asyncio.get_running_loop()
        self._thread = threading.get_ident()
        self._schedule(self._loop.time())
        if self.on_sample is not None:
            self.on_sample(self.sample())

    def last_tick(self) -> float:
        """Monotonic seconds of the loop's last tick (read from any thread)."""
        return self.last_tick_s

    def observe_receive(self, waited_s: float) -> None:
        """A client message waited ``waited_s`` between reaching the process and the app
        (on the loop's thread)."""
        self._receive_lag_s = max(self._receive_lag_s, waited_s)

    def stop(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None

    def sample(self) -> LoadSample:
        """The load over the window; on the loop's own thread the next tick, if already
        overdue, is a lag the loop has now (a batch of callbacks that runs for seconds holds
        the ticks back, and would otherwise leave the sample stale). The busy fraction runs
        to the last tick: admission asks for a sample per handshake, and reading the thread's
        CPU clock is a system call, where ``py-spy`` found a quarter of the loop's time in a
        storm of handshakes on a loaded machine (a system call is also where a preempted
        process is caught, so that share is an upper bound; docs/reports/hostile-clients.md)."""
        ticks = self.ticks
        overdue_s = 0.0
        if self._loop is not None and threading.get_ident() == self._thread:
            overdue_s = max(0.0, self._loop.time() - self._due)
        if len(ticks) < 2:
            return LoadSample(lag_ms=1000.0 * overdue_s, rss_mb=self.rss_mb)
        window = self._window_of(ticks)
        lag_s = max(window.lag_s, overdue_s)
        return LoadSample(1000.0 * lag_s, window.busy, self.rss_mb, 1000.0 * window.receive_lag_s)

    def _window_of(self, ticks: deque[_Tick]) -> _Window:
        """The window's figures, computed once per tick: admission asks for a sample per
        connection, hundreds of them between two ticks in a flood."""
        cached = self._window
        if cached is not None and cached.last is ticks[-1] and cached.ticks is ticks:
            return cached
        snapshot = list(ticks)  # the loop's thread may append while a pool thread reads
        first, last = snapshot[0], snapshot[-1]
        # Over at least a whole window: a few milliseconds after start the handshake under
        # way would otherwise count as a loop busy all the time.
        busy = (last.cpu - first.cpu) / max(last.wall - first.wall, self.window_s)
        later = snapshot[1:]
        self._window = _Window(
            ticks,
            last,
            min(busy, 1.0),
            statistics.median(tick.lag_s for tick in later),
            statistics.median(tick.receive_lag_s for tick in later),
        )
        return self._window

    def _schedule(self, now: float) -> None:
        assert self._loop is not None
        self._due = now + self.interval_s
        self._timer = self._loop.call_at(self._due, self._tick)

    def _tick(self) -> None:
        assert self._loop is not None
        now = self._loop.time()
        lag_s = max(0.0, now - self._due)
        self.ticks.append(_Tick(time.monotonic(), time.thread_time(), lag_s, self._receive_lag_s))
        self._receive_lag_s = 0.0
        self.last_tick_s = time.monotonic()
        self.rss_mb = resident_mb()
        self._schedule(now)
        if self.on_sample is not None:
            self.on_sample(self.sample())


def resident_mb() -> float:
    """This process's resident set size in MiB (Linux: now; elsewhere: its peak)."""
    try:
        pages = int(Path("/proc/self/statm").read_text().split()[1])
        return pages * os.sysconf("SC_PAGE_SIZE") / MIB
    except (OSError, ValueError, IndexError):
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        return peak / MIB if sys.platform == "darwin" else peak / 1024


def machine_memory_mb() -> float:
    """The memory this process may use, in MiB: physical memory, or a smaller cgroup limit."""
    total = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    for path in CGROUP_LIMITS:
        try:
            text = path.read_text().strip()
        except OSError:
            continue
        if text.isdigit():
            total = min(total, int(text))
    return total / MIB
