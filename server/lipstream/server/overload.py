"""Whether the process can take more work: a verdict from measured load, without I/O.

Sketch: a session costs the event loop CPU for as long as it streams, and the loop serves
every session, so once the loop is saturated each new session adds lag to all of them. A
fixed session cap cannot know where that point is (it depends on the engine, the machine,
the clients' message rate), so ``OverloadPolicy`` admits a new session only while the
measured load (``load.LoadSample``) leaves room:

- resident memory at most ``max_memory_mb`` (also checked for every ``start`` and
  ``POST /v1/synthesize``: past it nothing new is taken on, while work under way finishes);
- the event-loop lag at most ``max_lag_ms``, once ``LAG_FROM_SESSIONS`` sessions are open
  (with fewer, a lagging loop says more about the machine, other processes taking its
  cores, than about the sessions, and refusing more would not relieve it);
- the loop's busy fraction over the last ``RECENT_S`` (the monitor's window), plus the cost
  of this session and of those admitted within that window, at most ``max_busy``. A session
  admitted ``age`` seconds ago counts with weight ``1 - age / RECENT_S``: the window has
  measured that part of it streaming already. Without this a burst of connections would all
  be admitted before the first of them shows in the measurement. A session's cost is the
  learned one once there is one: the busy fraction per open session, averaged over the
  samples taken with at least ``LEARN_FROM_SESSIONS`` sessions open (fewer say more about
  the clients than about the sessions); before that, the calibrated one
  (``calibrated_session_cost``: the costliest loaded model's default rung, at one phoneme per
  ``PHONEME_S`` of speech, as start-up calibration measured it, plus
  ``MESSAGE_OVERHEAD_MS`` per message for the work outside the engine, as profiled in
  docs/reports/throughput.md).

A refusal through the WebSocket (accept, ``error``, close) costs the loop about as much as
a short request; in a storm of connections those refusals alone keep the loop behind. So
while the lag exceeds ``SHED_FACTOR`` times its limit (``shedding``), the HTTP protocol
answers new upgrades with 503 and ``Retry-After`` before any WebSocket work
(``handshake``).

Left at 0, the memory ceiling is ``AUTO_MEMORY_SHARE`` of the memory the process may use
(the machine's, or a smaller container limit) divided among the workers. A refusal is
``server_busy`` with ``retry_after_ms``: ``RETRY_AFTER_MS`` (the time the load
measurement needs to see the effect of sessions leaving) or ``MEMORY_RETRY_AFTER_MS``, plus a
random part of up to as much again, so that clients refused together do not all return at
the same instant.
"""

from __future__ import annotations

import random
import time
from collections import deque
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field

from lipstream_client.errors import SERVER_BUSY
from lipstream_client.messages import JsonValue

from ..config import ServerSettings
from .budget import RungEstimate
from .calibration import PHONEME_S
from .catalog import Catalog
from .load import LoadMonitor, LoadSample, machine_memory_mb

RECENT_S = 1.0
RETRY_AFTER_MS = 1000
MEMORY_RETRY_AFTER_MS = 5000
LEARN_FROM_SESSIONS = 16
LAG_FROM_SESSIONS = 16
SHED_FACTOR = 4.0
LEARN_WEIGHT = 0.1
AUTO_MEMORY_SHARE = 0.8
MESSAGE_OVERHEAD_MS = 0.13  # uvicorn, websockets, codec and session per message in and out


@dataclass(frozen=True)
class Refusal:
    """Why new work is refused now (``reason``: memory, loop_lag, loop_busy or sessions), and
    when to ask again."""

    reason: str
    message: str
    retry_after_ms: int
    code: str = SERVER_BUSY

    @property
    def details(self) -> dict[str, JsonValue]:
        return {"retry_after_ms": self.retry_after_ms, "reason": self.reason}


@dataclass(frozen=True)
class LoadLimits:
    """The thresholds (``ServerSettings``) and the calibrated cost of one session, as a
    fraction of one core."""

    max_memory_mb: float
    max_lag_ms: float
    max_busy: float
    session_cost: float


def calibrated_session_cost(ladders: Iterable[Sequence[RungEstimate]]) -> float:
    """The fraction of one core a session of real-time speech (one phoneme per
    ``PHONEME_S``, one message each) needs: the costliest model's default rung plus
    ``MESSAGE_OVERHEAD_MS`` per message."""
    per_phoneme_ms = max((ladder[0].per_phoneme_ms for ladder in ladders if ladder), default=0.0)
    return (per_phoneme_ms + MESSAGE_OVERHEAD_MS) / (1000.0 * PHONEME_S)


@dataclass
class OverloadPolicy:
    """The admission verdicts; ``now`` is monotonic time in seconds."""

    limits: LoadLimits
    rng: random.Random = field(default_factory=random.Random)
    recent: deque[float] = field(default_factory=deque)
    learned_cost: float = 0.0

    @property
    def session_cost(self) -> float:
        return self.learned_cost or self.limits.session_cost

    def request_refusal(self, load: LoadSample) -> Refusal | None:
        """A refusal for a new request (``start``, ``POST /v1/synthesize``) while memory is
        above its ceiling."""
        ceiling = self.limits.max_memory_mb
        if load.rss_mb > ceiling:
            return self._refusal(
                "memory",
                f"the server's memory ({load.rss_mb:.0f} MiB) is above its ceiling "
                f"({ceiling:.0f} MiB)",
                MEMORY_RETRY_AFTER_MS,
            )
        return None

    def session_refusal(self, load: LoadSample, sessions: int, now: float) -> Refusal | None:
        """A refusal for a new session with ``sessions`` open, or None after counting it as
        admitted at ``now``."""
        self._learn(load, sessions)
        while self.recent and now - self.recent[0] >= RECENT_S:
            self.recent.popleft()
        refusal = self.request_refusal(load)
        limits = self.limits
        unmeasured = sum(1.0 - (now - admitted) / RECENT_S for admitted in self.recent)
        projected = load.loop_busy + (unmeasured + 1.0) * self.session_cost
        lagging = load.lag_ms > limits.max_lag_ms and sessions >= LAG_FROM_SESSIONS
        if refusal is None and lagging:
            refusal = self._refusal(
                "loop_lag",
                f"the server's event loop lags {load.lag_ms:.0f} ms behind, more than "
                f"{limits.max_lag_ms:g} ms",
                RETRY_AFTER_MS,
            )
        if refusal is None and projected > limits.max_busy:
            refusal = self._refusal(
                "loop_busy",
                f"another session would make the server's event loop {100 * projected:.0f} % "
                f"busy, more than {100 * limits.max_busy:.0f} %",
                RETRY_AFTER_MS,
            )
        if refusal is None:
            self.recent.append(now)
        return refusal

    def shedding(self, load: LoadSample, sessions: int) -> bool:
        """Whether the loop lags so far behind (``SHED_FACTOR`` x ``max_lag_ms``, with
        ``LAG_FROM_SESSIONS`` sessions open) that even refusing a WebSocket with an
        ``error`` costs too much: new upgrades then get HTTP 503 before any WebSocket work."""
        return sessions >= LAG_FROM_SESSIONS and load.lag_ms > SHED_FACTOR * self.limits.max_lag_ms

    def sessions_refusal(self, max_sessions: int) -> Refusal:
        return self._refusal(
            "sessions",
            f"the server is at its limit of {max_sessions} sessions",
            RETRY_AFTER_MS,
        )

    def _learn(self, load: LoadSample, sessions: int) -> None:
        if sessions < LEARN_FROM_SESSIONS:
            return
        observed = load.loop_busy / sessions
        if self.learned_cost == 0.0:
            self.learned_cost = observed
        else:
            self.learned_cost += LEARN_WEIGHT * (observed - self.learned_cost)

    def _refusal(self, reason: str, what: str, base_ms: int) -> Refusal:
        retry_after_ms = base_ms + self.rng.randrange(base_ms)
        message = f"{what}; retry in {retry_after_ms} ms (details.retry_after_ms)"
        return Refusal(reason, message, retry_after_ms)


@dataclass
class Overload:
    """The policy fed by a running ``LoadMonitor``: what the routes ask."""

    policy: OverloadPolicy
    monitor: LoadMonitor

    def session_refusal(self, sessions: int) -> Refusal | None:
        return self.policy.session_refusal(self.monitor.sample(), sessions, time.monotonic())

    def shedding(self, sessions: int) -> bool:
        return self.policy.shedding(self.monitor.sample(), sessions)

    def request_refusal(self) -> Refusal | None:
        """Memory only, from the monitor's latest figure: safe from the synthesis pool's
        threads, where a session may handle its ``start``."""
        return self.policy.request_refusal(LoadSample(rss_mb=self.monitor.rss_mb))


def memory_ceiling_mb(settings: ServerSettings) -> float:
    """``LIPSTREAM_MAX_MEMORY_MB``, or when 0, ``AUTO_MEMORY_SHARE`` of the memory the
    process may use (``load.machine_memory_mb``) divided among the workers."""
    if settings.max_memory_mb:
        return float(settings.max_memory_mb)
    return AUTO_MEMORY_SHARE * machine_memory_mb() / settings.workers


def overload_for(
    settings: ServerSettings,
    catalog: Catalog,
    on_sample: Callable[[LoadSample], None] | None = None,
) -> Overload:
    """The admission of a server with ``settings`` serving ``catalog``'s models, its monitor
    (which passes each sample to ``on_sample``) not yet started."""
    ladders = [facts.ladder for facts in catalog.facts.values()]
    limits = LoadLimits(
        memory_ceiling_mb(settings),
        settings.max_loop_lag_ms,
        settings.max_loop_busy,
        calibrated_session_cost(ladders),
    )
    return Overload(OverloadPolicy(limits), LoadMonitor(on_sample=on_sample))
