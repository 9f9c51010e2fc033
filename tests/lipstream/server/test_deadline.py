"""``SendDeadline``: one timer per connection cancels exactly the send that overran.
``LaterDeadline``: a deadline that moves later fires once, at its last position.

Each scenario runs on virtual loop time (``run_on_virtual_time``): sleeps and timers take
exactly their due times, so a loaded machine cannot stretch a send past its deadline."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from lipstream.server.deadline import LaterDeadline, SendDeadline
from tests.helpers import run_on_virtual_time

TIMEOUT_S = 0.2


async def _send(deadline: SendDeadline, seconds: float) -> tuple[float, bool]:
    """A send that takes ``seconds``: how long it ran, and whether the deadline cut it."""
    task = asyncio.current_task()
    assert task is not None
    loop = asyncio.get_running_loop()
    began = loop.time()
    deadline.started(task)
    try:
        await asyncio.sleep(seconds)
    except asyncio.CancelledError:
        assert deadline.expired and task.uncancel() == 0
        return loop.time() - began, True
    finally:
        deadline.stopped()
    return loop.time() - began, False


def test_sends_within_the_deadline_are_left_alone_and_the_timer_lapses() -> None:
    async def scenario() -> tuple[list[tuple[float, bool]], bool, bool]:
        deadline = SendDeadline(asyncio.get_running_loop(), TIMEOUT_S)
        sends = [await _send(deadline, 0.05) for _ in range(6)]  # 0.3 s in all: past one timeout
        await asyncio.sleep(TIMEOUT_S)
        return sends, deadline.expired, deadline.pending

    sends, expired, pending = run_on_virtual_time(lambda _: scenario())
    assert not expired and not pending
    assert [cut for _, cut in sends] == [False] * 6


def test_a_stuck_send_is_cut_at_its_own_deadline_not_at_the_timers_first_check() -> None:
    async def scenario() -> tuple[tuple[float, bool], tuple[float, bool]]:
        deadline = SendDeadline(asyncio.get_running_loop(), TIMEOUT_S)
        first = await _send(deadline, 0.15)  # arms the timer for t = 0.2
        stuck = await _send(deadline, 5.0)  # started at >= 0.15: due 0.2 s later, not at 0.2
        return first, stuck

    (_, first_cut), (stuck_s, stuck_cut) = run_on_virtual_time(lambda _: scenario())
    assert not first_cut and stuck_cut
    # Cut at the timer's first check it would have run 0.2 - 0.15 = 0.05 s.
    assert stuck_s == pytest.approx(TIMEOUT_S)


def test_disarm_cancels_the_pending_timer() -> None:
    async def scenario() -> bool:
        deadline = SendDeadline(asyncio.get_running_loop(), TIMEOUT_S)
        task = asyncio.current_task()
        assert task is not None
        deadline.started(task)
        deadline.disarm()
        await asyncio.sleep(TIMEOUT_S * 1.5)  # a live timer would cancel this sleep
        return deadline.expired

    assert run_on_virtual_time(lambda _: scenario()) is False


def test_a_deadline_moved_later_fires_once_at_its_last_position() -> None:
    async def scenario() -> tuple[list[float], float, int, float]:
        loop = asyncio.get_running_loop()
        began = loop.time()
        deadline_at = [began + TIMEOUT_S]
        fired: list[float] = []
        timers = 0
        call_at = loop.call_at

        def counting_call_at(
            when: float, callback: Any, *args: Any, **kwargs: Any
        ) -> asyncio.TimerHandle:
            nonlocal timers
            timers += getattr(callback, "__self__", None) is deadline
            return call_at(when, callback, *args, **kwargs)

        loop.call_at = counting_call_at  # type: ignore[method-assign,assignment]  # counts the loop's timers
        deadline = LaterDeadline(loop, lambda: deadline_at[0], lambda: fired.append(loop.time()))
        for _ in range(20):  # a message every 0.02 s moves the deadline on
            deadline.arm(deadline_at[0])
            await asyncio.sleep(0.02)
            deadline_at[0] = loop.time() + TIMEOUT_S
        moving_s = loop.time() - began
        deadline.arm(deadline_at[0])
        await asyncio.sleep(2 * TIMEOUT_S)
        return [at - began for at in fired], deadline_at[0] - began, timers, moving_s

    fired, last_due, timers, moving_s = run_on_virtual_time(lambda _: scenario())
    assert moving_s == pytest.approx(20 * 0.02)
    assert fired == [pytest.approx(last_due)]
    # a timer per timeout period the deadline moved through (and the last), not one per arm
    assert timers <= moving_s / TIMEOUT_S + 2 < 21


def test_a_deadline_that_lapses_calls_nothing_and_disarm_cancels() -> None:
    async def scenario() -> list[str]:
        loop = asyncio.get_running_loop()
        calls: list[str] = []
        gone = LaterDeadline(loop, lambda: None, lambda: calls.append("gone"))
        gone.arm(loop.time() + 0.05)
        disarmed = LaterDeadline(loop, lambda: loop.time(), lambda: calls.append("disarmed"))
        disarmed.arm(loop.time() + 0.05)
        disarmed.disarm()
        await asyncio.sleep(0.15)
        return calls

    assert run_on_virtual_time(lambda _: scenario()) == []
