"""``SendDeadline``: one timer per connection cancels exactly the send that overran."""

from __future__ import annotations

import asyncio

import pytest

from lipstream.server.deadline import SendDeadline

TIMEOUT_S = 0.2


async def _send(deadline: SendDeadline, seconds: float) -> float:
    """A send that takes ``seconds``; returns how long it ran before finishing or being cut."""
    task = asyncio.current_task()
    assert task is not None
    loop = asyncio.get_running_loop()
    began = loop.time()
    deadline.started(task)
    try:
        await asyncio.sleep(seconds)
    except asyncio.CancelledError:
        assert deadline.expired and task.uncancel() == 0
        return loop.time() - began
    finally:
        deadline.stopped()
    return loop.time() - began


def test_sends_within_the_deadline_are_left_alone_and_the_timer_lapses() -> None:
    async def scenario() -> tuple[list[float], bool, object]:
        deadline = SendDeadline(asyncio.get_running_loop(), TIMEOUT_S)
        spent = [await _send(deadline, 0.05) for _ in range(6)]  # 0.3 s in all: past one timeout
        await asyncio.sleep(TIMEOUT_S)
        return spent, deadline.expired, deadline._timer

    spent, expired, timer = asyncio.run(scenario())
    assert not expired and timer is None
    assert all(0.05 <= seconds < 0.1 for seconds in spent)


def test_a_stuck_send_is_cut_at_its_own_deadline_not_at_the_timers_first_check() -> None:
    async def scenario() -> tuple[float, float]:
        deadline = SendDeadline(asyncio.get_running_loop(), TIMEOUT_S)
        first = await _send(deadline, 0.15)  # arms the timer for t = 0.2
        stuck = await _send(deadline, 5.0)  # started at 0.15: due at 0.35, not 0.2
        return first, stuck

    first, stuck = asyncio.run(scenario())
    assert first == pytest.approx(0.15, abs=0.04)
    assert stuck == pytest.approx(TIMEOUT_S, abs=0.04)


def test_disarm_cancels_the_pending_timer() -> None:
    async def scenario() -> bool:
        deadline = SendDeadline(asyncio.get_running_loop(), TIMEOUT_S)
        task = asyncio.current_task()
        assert task is not None
        deadline.started(task)
        deadline.disarm()
        await asyncio.sleep(TIMEOUT_S * 1.5)  # a live timer would cancel this sleep
        return deadline.expired

    assert asyncio.run(scenario()) is False
