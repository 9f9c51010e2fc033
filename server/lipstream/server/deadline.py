"""A connection's deadlines, each kept with one timer per connection, not per message.

Sketch: ``LaterDeadline`` keeps a deadline that only ever moves later with one
timer. Arming keeps a pending timer, which is then early; when it fires it
asks for the deadline again and re-arms for it, calls ``on_due`` once it has
passed, or lapses when there is none. A deadline moved on by every message
thus costs a timer per period it moves through, not one per message: at
thousands of messages per second ``asyncio.timeout`` around each (a heap
entry each, cancelled ones lingering until their time) would cost more than
the sends and receives themselves.

Two deadlines use it. Every WebSocket send must finish within ``timeout_s``,
because a client that stops reading pins ``await send`` forever
(``SendDeadline``): the deadline is the send in progress's start plus
``timeout_s``, and when it passes the sending task is cancelled and
``expired`` set (the task turns that cancellation into ``TimeoutError``); each
send thus fails exactly at its own deadline. The request timeout ends the
wait for a client's next message at the session's ``next_expiry``, which each
message moves on.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any


class SendDeadline:
    """Cancels a task whose current send has lasted ``timeout_s`` seconds (loop time)."""

    def __init__(self, loop: asyncio.AbstractEventLoop, timeout_s: float) -> None:
        self.loop = loop
        self.timeout_s = timeout_s
        self.expired = False
        self._since: float | None = None
        self._task: asyncio.Task[Any] | None = None
        self._timer = LaterDeadline(loop, self._due, self._expire)

    @property
    def pending(self) -> bool:
        """A timer is armed."""
        return self._timer.pending

    def started(self, task: asyncio.Task[Any]) -> None:
        """``task`` begins a send now."""
        self._since = self.loop.time()
        self._task = task
        self._timer.arm(self._since + self.timeout_s)

    def stopped(self) -> None:
        """The send begun last has finished (or failed)."""
        self._since = None
        self._task = None

    def disarm(self) -> None:
        """Cancel the pending timer (the connection is over)."""
        self._timer.disarm()

    def _due(self) -> float | None:
        return None if self._since is None else self._since + self.timeout_s

    def _expire(self) -> None:
        if self._task is not None:
            self.expired = True
            self._task.cancel()


class LaterDeadline:
    """Calls ``on_due`` once the deadline ``due()`` (loop time; None: none) has passed,
    for a deadline that never moves earlier while armed."""

    def __init__(
        self,
        loop: asyncio.AbstractEventLoop,
        due: Callable[[], float | None],
        on_due: Callable[[], None],
    ) -> None:
        self.loop = loop
        self.due = due
        self.on_due = on_due
        self._timer: asyncio.TimerHandle | None = None

    @property
    def pending(self) -> bool:
        """A timer is armed."""
        return self._timer is not None

    def arm(self, when: float) -> None:
        """Make sure a timer fires by ``when``, the deadline now (a pending timer is never
        later than it, since the deadline only moves later)."""
        if self._timer is None:
            self._timer = self.loop.call_at(when, self._check)

    def disarm(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None

    def _check(self) -> None:
        self._timer = None
        due = self.due()
        if due is None:
            return
        if self.loop.time() >= due:
            self.on_due()
        else:
            self._timer = self.loop.call_at(due, self._check)
