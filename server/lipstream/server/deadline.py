"""A connection's deadlines, each kept with one timer per connection, not per message.

Sketch: every WebSocket send must finish within ``timeout_s``, because a
client that stops reading pins ``await send`` forever. ``asyncio.timeout``
around each send would arm and cancel a timer per message: at thousands of
messages per second that bookkeeping (a heap entry each, cancelled ones
lingering for ``timeout_s``) costs more than the sends, which almost never
wait. Instead the connection marks when a send starts and stops. Starting a
send arms a timer only if none is pending. When the timer fires it looks at
the send in progress, if any: started ``timeout_s`` ago or more, it cancels
the sending task and sets ``expired`` (the task turns that cancellation
into ``TimeoutError``); started later, it re-arms for that send's due time;
none, it lapses. Each send thus fails exactly at its own deadline, and a
busy connection re-arms at most once per ``timeout_s``.

``LaterDeadline`` does the same for a deadline that only ever moves later,
such as the request timeout (each message moves its request's expiry on):
arming keeps the pending timer, which is then early; when it fires it asks
for the deadline again and re-arms for it, or calls ``on_due`` once it has
passed. The wait for a client's message thus arms a timer once per timeout
period, not once per message.
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
        self._timer: asyncio.TimerHandle | None = None

    def started(self, task: asyncio.Task[Any]) -> None:
        """``task`` begins a send now."""
        self._since = self.loop.time()
        self._task = task
        if self._timer is None:
            self._timer = self.loop.call_at(self._since + self.timeout_s, self._check)

    def stopped(self) -> None:
        """The send begun last has finished (or failed)."""
        self._since = None
        self._task = None

    def disarm(self) -> None:
        """Cancel the pending timer (the connection is over)."""
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None

    def _check(self) -> None:
        self._timer = None
        since, task = self._since, self._task
        if since is None or task is None:
            return
        due = since + self.timeout_s
        if self.loop.time() >= due:
            self.expired = True
            task.cancel()
        else:
            self._timer = self.loop.call_at(due, self._check)


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
