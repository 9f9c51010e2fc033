"""Stopping engine work: one token per request that long loops check between steps.

Sketch: a ``WorkGuard`` carries a cancellation flag and an optional budget of
seconds on a clock (by default the calling thread's CPU time, so time spent
waiting for the GIL or for a core does not count). Whoever calls the engine
wraps each call in ``metering()``, which adds the call's time to ``spent_s``;
the engine's long loops (PQ-Matching's windows and branches, the placement of
tiles, frame rendering) call ``check()``, which raises ``WorkCancelled`` once
``cancel()`` was called (from any thread: it only sets a flag) and the
guard's ``exceeded`` error once the budget is spent. A synthesizer that raised
either is left mid-step: its request must end.

A call may be metered on another clock (``metering(clock)``): the server meters
the short calls it runs on the event loop by wall time, because reading a
thread's CPU clock is a system call that costs several microseconds on virtual
machines, and was most of the loop's cost of a cheap message.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from types import TracebackType

from ..errors import LipstreamError

CPU_BUDGET_EXCEEDED = "cpu_budget_exceeded"


class WorkCancelled(LipstreamError):
    """The request's work was cancelled (its connection closed, or the client sent ``cancel``)."""

    code = "work_cancelled"


class CpuBudgetExceeded(LipstreamError):
    """The request used up its CPU budget."""

    code = CPU_BUDGET_EXCEEDED


class WorkGuard:
    """A cancellation flag and a budget of ``budget_s`` seconds of ``clock`` (None: no budget);
    ``exceeded(spent_s, budget_s)`` is the error raised once the budget is spent."""

    def __init__(
        self,
        budget_s: float | None = None,
        clock: Callable[[], float] = time.thread_time,
        exceeded: Callable[[float, float], LipstreamError] | None = None,
    ) -> None:
        self.budget_s = budget_s
        self.clock = clock
        self.exceeded = exceeded or _cpu_budget_exceeded
        self.cancelled = False
        self.spent_s = 0.0
        self.block_since: float | None = None
        self.block_clock = clock

    def cancel(self) -> None:
        """Stop the work at its next ``check`` (safe from any thread)."""
        self.cancelled = True

    def used_s(self) -> float:
        """Seconds spent so far, including the call being metered."""
        running = 0.0 if self.block_since is None else self.block_clock() - self.block_since
        return self.spent_s + running

    def check(self) -> None:
        """Raise ``WorkCancelled`` after ``cancel``, the budget's error once it is spent."""
        if self.cancelled:
            raise WorkCancelled("the request's work was cancelled", where="work")
        if self.budget_s is not None:
            used = self.used_s()
            if used > self.budget_s:
                raise self.exceeded(used, self.budget_s)

    def metering(self, clock: Callable[[], float] | None = None) -> Metering:
        """Count the block's time (on ``clock``, by default the guard's) as spent; blocks do
        not nest, and each starts with a ``check``."""
        return Metering(self, clock or self.clock)


class Metering:
    """The context manager of ``WorkGuard.metering`` (a class, not a generator: it wraps
    every message a session handles)."""

    __slots__ = ("guard", "clock")

    def __init__(self, guard: WorkGuard, clock: Callable[[], float]) -> None:
        self.guard = guard
        self.clock = clock

    def __enter__(self) -> None:
        guard = self.guard
        guard.check()
        guard.block_clock = self.clock
        guard.block_since = self.clock()

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        guard = self.guard
        if guard.block_since is not None:
            guard.spent_s += self.clock() - guard.block_since
        guard.block_since = None


def _cpu_budget_exceeded(spent_s: float, budget_s: float) -> LipstreamError:
    return CpuBudgetExceeded(
        f"the request used {spent_s:.3g} s of CPU, over its budget of {budget_s:g} s",
        where="work",
    )
