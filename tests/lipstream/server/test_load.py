"""The load monitor: its summary of hand-made ticks, and its sampling on a real event loop."""

from __future__ import annotations

import asyncio
import os
import statistics
from collections import deque
from collections.abc import Iterable

import pytest

from lipstream.server.load import LoadMonitor, LoadSample, _Tick, machine_memory_mb, resident_mb
from tests.helpers import VirtualClock, run_on_virtual_time


def test_the_sample_is_the_median_lag_and_the_busy_fraction_of_the_window() -> None:
    monitor = LoadMonitor(interval_s=0.1, window_s=0.4)
    monitor.rss_mb = 321.0
    assert monitor.sample() == LoadSample(rss_mb=321.0)  # nothing measured yet
    # (wall s, loop-thread CPU s, lag s): 0.3 s of CPU in 0.4 s; lags 0.002, 0.5, 0.004, 0.001
    monitor.ticks = deque(
        [
            _Tick(10.0, 5.0, 0.0),
            _Tick(10.1, 5.05, 0.002),
            _Tick(10.2, 5.1, 0.5),
            _Tick(10.3, 5.2, 0.004),
            _Tick(10.4, 5.3, 0.001),
        ],
        maxlen=5,
    )
    sample = monitor.sample()
    assert abs(sample.loop_busy - 0.75) < 1e-9
    assert abs(sample.lag_ms - 3.0) < 1e-9  # median of 2, 500, 4, 1 ms: one stall is ignored
    assert sample.rss_mb == 321.0


def test_the_windows_figures_are_computed_once_per_tick(monkeypatch: pytest.MonkeyPatch) -> None:
    """Admission samples once per connection; the medians change only with a tick."""
    medians: list[list[float]] = []
    median = statistics.median

    def counted_median(values: Iterable[float]) -> float:
        listed = list(values)
        medians.append(listed)
        return median(listed)

    monkeypatch.setattr(statistics, "median", counted_median)
    monitor = LoadMonitor(interval_s=0.1, window_s=0.2)
    monitor.ticks = deque([_Tick(10.0, 5.0, 0.0), _Tick(10.1, 5.05, 0.002)], maxlen=3)
    first = [monitor.sample() for _ in range(5)]
    assert len(medians) == 2 and first[0] == first[-1]
    assert first[0].lag_ms == pytest.approx(2.0)
    monitor.ticks.append(_Tick(10.2, 5.1, 0.010))  # what the loop's tick does
    later = monitor.sample()
    assert len(medians) == 4 and medians[-2] == [0.002, 0.010]
    assert later.lag_ms == pytest.approx(6.0) and later.loop_busy == pytest.approx(0.5)
    monitor.rss_mb = 99.0  # the memory figure is read fresh each time
    assert monitor.sample().rss_mb == 99.0 and len(medians) == 4


def test_the_window_keeps_its_length_of_ticks() -> None:
    async def run() -> LoadMonitor:
        monitor = LoadMonitor(interval_s=0.01, window_s=0.05)
        monitor.start()
        for _ in range(500):
            if len(monitor.ticks) == monitor.ticks.maxlen:
                break
            await asyncio.sleep(0.01)
        await asyncio.sleep(0.05)
        monitor.stop()
        return monitor

    monitor = run_on_virtual_time(lambda _: run())
    walls = [tick.wall for tick in monitor.ticks]
    assert len(walls) == 6 and walls == sorted(walls)
    assert all(tick.lag_s >= 0.0 for tick in monitor.ticks)
    sample = monitor.sample()
    assert 0.0 <= sample.loop_busy <= 1.0


def test_memory_figures_are_of_this_process_and_this_machine() -> None:
    page = os.sysconf("SC_PAGE_SIZE")
    with open("/proc/self/statm") as statm:
        pages_before = int(statm.read().split()[1])
    resident = resident_mb()
    with open("/proc/self/statm") as statm:
        pages_after = int(statm.read().split()[1])
    low, high = sorted((pages_before, pages_after))
    assert low * page / (1 << 20) * 0.9 <= resident <= high * page / (1 << 20) * 1.1
    physical = os.sysconf("SC_PHYS_PAGES") * page / (1 << 20)
    assert resident < machine_memory_mb() <= physical


def test_a_loop_held_up_shows_its_lag_before_the_next_tick_runs() -> None:
    """A long batch of callbacks holds the ticks back; sampled from inside it, the overdue
    tick is the lag: the hold minus the interval to the tick that was due."""

    async def held(clock: VirtualClock) -> LoadSample:
        monitor = LoadMonitor(interval_s=0.1, window_s=1.0)
        monitor.start()  # the first tick is due at 0.1 s
        clock.now += 0.3  # the loop is held for 0.3 s: no tick can run
        during = monitor.sample()
        monitor.stop()
        return during

    assert run_on_virtual_time(held).lag_ms == pytest.approx(200.0)


def test_busy_time_is_spread_over_at_least_a_whole_window() -> None:
    monitor = LoadMonitor(interval_s=0.1, window_s=1.0)
    # 4 ms of CPU within 5 ms just after start: 0.4 % of the window, not 80 % of a core
    monitor.ticks = deque([_Tick(10.0, 5.0, 0.0), _Tick(10.005, 5.004, 0.0)], maxlen=11)
    assert abs(monitor.sample().loop_busy - 0.004) < 1e-9
