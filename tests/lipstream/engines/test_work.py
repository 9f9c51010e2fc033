"""WorkGuard: cancellation and a budget on a clock, checked between steps of engine work."""

from __future__ import annotations

import pytest

from lipstream.engines.work import CpuBudgetExceeded, WorkCancelled, WorkGuard
from lipstream.errors import LipstreamError


class FakeClock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def test_metering_adds_each_block_and_check_raises_once_the_budget_is_spent() -> None:
    clock = FakeClock()
    guard = WorkGuard(1.0, clock)
    with guard.metering():
        clock.now += 0.4
    clock.now += 5.0  # time outside a metered call is not the request's
    with guard.metering():
        clock.now += 0.5
        guard.check()  # 0.9 s used, within 1 s
        clock.now += 0.2
        with pytest.raises(CpuBudgetExceeded) as raised:
            guard.check()  # 1.1 s used
    assert raised.value.code == "cpu_budget_exceeded"
    assert guard.spent_s == pytest.approx(1.1)
    with pytest.raises(CpuBudgetExceeded):
        with guard.metering():  # a new call starts with a check
            raise AssertionError("not reached")


def test_cancel_stops_at_the_next_check_whatever_the_budget() -> None:
    guard = WorkGuard()
    guard.check()
    guard.cancel()
    with pytest.raises(WorkCancelled):
        guard.check()


def test_an_engine_budget_raises_its_own_error() -> None:
    clock = FakeClock()

    def timeout(spent: float, budget: float) -> LipstreamError:
        return LipstreamError(f"{spent:g} of {budget:g}", code="search_timeout")

    guard = WorkGuard(0.25, clock, timeout)
    with guard.metering():
        clock.now += 0.5
    with pytest.raises(LipstreamError) as raised:
        guard.check()
    assert (raised.value.code, raised.value.message) == ("search_timeout", "0.5 of 0.25")


def test_a_block_metered_on_another_clock_counts_that_clock_only() -> None:
    cpu, wall = FakeClock(), FakeClock()
    guard = WorkGuard(1.0, cpu)
    with guard.metering(wall):
        wall.now += 0.3
        cpu.now += 7.0  # the guard's own clock is not read for this block
        assert guard.used_s() == pytest.approx(0.3)
    with guard.metering():
        cpu.now += 0.5
        wall.now += 9.0
    assert guard.spent_s == pytest.approx(0.8)
