"""Whether the process can take more work: a verdict from measured load, without I/O.

Sketch: a session costs the event loop CPU for as long as it streams, and the loop serves
every session, so once the loop is saturated each new session adds lag to all of them. A
fixed session cap cannot know where that point is (it depends on the engine, the machine,
the clients' message rate), so ``OverloadPolicy`` admits a new session only while the
measured load (``load.LoadSample``) leaves room:

- resident memory at most ``max_memory_mb`` (also checked for every ``start`` and
  ``POST /v1/synthesize``: past it nothing new is taken on, while work under way finishes;
  the audio that requests take in later is counted as it arrives, ``held_input``);
- the lag at most ``max_lag_ms``, once ``LAG_FROM_SESSIONS`` sessions are open (with fewer,
  a lagging loop says more about the machine, other processes taking its cores, than about
  the sessions, and refusing more would not relieve it). Two lags count: the event loop's
  (how late its timer runs: ``loop_lag``) and the receive lag (how long client messages
  wait between the socket's bytes reaching the process and the app taking them:
  ``receive_lag``), which is where a storm's queueing shows first;
- the loop's CPU: its busy fraction over the last ``RECENT_S`` (the monitor's window), plus
  the cost of what that window has not measured yet, plus this session's, at most
  ``max_busy``. Not measured yet are the sessions admitted that have not started a request
  (*pending*: a whole session each, for as long as they stay pending), and those that
  started their first request ``age`` seconds ago (weight ``1 - age / RECENT_S``: the
  window has measured that part of it streaming already). Without this a burst of
  connections would all be admitted before the first of them shows in the measurement.

A session's engine is known only at its first ``start``, so its price is paid twice: at the
handshake, as a pending session, at the cheapest engine's cost (``session_cost``), and at
that ``start``, at its engine's cost (``start_refusal``; a refusal ends only that request,
and the session stays unpriced until a later ``start`` fits). So one engine's cost never
refuses another engine's sessions. An engine's cost is the calibrated one
(``calibrated_session_cost``: its costliest model's default rung, at one phoneme per
``PHONEME_S`` of speech, as start-up calibration measured it, plus ``MESSAGE_OVERHEAD_MS``
per message for the work outside the engine, as profiled in docs/reports/throughput.md), or
the learned one when that is higher: the busy fraction per streaming session (those with a
request active, less the part of the recent starters the window has not measured), averaged
over the samples taken with at least ``LEARN_FROM_SESSIONS`` of them (fewer say more about
the clients than about the sessions). Pending sessions are not counted in it: a burst of
connections that have not started yet would otherwise make each session look cheap just
when the burst needs it to look dear.

A refusal through the WebSocket (accept, ``error``, close) costs the loop about as much as
a short request; in a storm of connections those refusals alone keep the loop behind. So
the HTTP protocol decides admission itself, when a WebSocket upgrade's head is parsed and
before any WebSocket work (``handshake``): a refused upgrade gets HTTP 503 with the
``server_busy`` error as its JSON body and ``Retry-After``; an admitted one is pending from
that moment, under the key ``Upgrade(client)`` (kept apart, in the order admitted, so the
stale ones are dropped from the front), so the next head of the same burst already
counts it, and the WebSocket endpoint ``adopt``s it under its connection. An upgrade the
endpoint never adopts (the client left during the handshake) stops counting after
``UPGRADE_TTL_S``. While the lag exceeds ``SHED_FACTOR`` times its limit (``shedding``),
upgrades get the same 503 without a verdict.

Left at 0, the memory ceiling is ``AUTO_MEMORY_SHARE`` of the memory the process may use
(the machine's, or a smaller container limit) divided among the workers. A refusal is
``server_busy`` with ``retry_after_ms``: ``RETRY_AFTER_MS`` (the time the load
measurement needs to see the effect of sessions leaving) or ``MEMORY_RETRY_AFTER_MS``, plus a
random part of up to as much again, so that clients refused together do not all return at
the same instant.
"""

from __future__ import annotations

import random
import threading
import time
from collections import deque
from collections.abc import Callable, Hashable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field

from lipstream_client.errors import SERVER_BUSY
from lipstream_client.messages import JsonValue

from ..config import ServerSettings
from .budget import RungEstimate
from .calibration import PHONEME_S
from .catalog import Catalog
from .load import LoadMonitor, LoadSample, machine_memory_mb

RECENT_S = 1.0
RATE_WINDOW_S = 0.1
RATE_RETRY_AFTER_MS = 500
RETRY_AFTER_MS = 1000
MEMORY_RETRY_AFTER_MS = 5000
LEARN_FROM_SESSIONS = 16
LAG_FROM_SESSIONS = 16
SHED_FACTOR = 4.0
LEARN_WEIGHT = 0.1
AUTO_MEMORY_SHARE = 0.8
UPGRADE_TTL_S = 10.0  # at least the head deadline plus a WebSocket handshake
MESSAGE_OVERHEAD_MS = 0.13  # uvicorn, websockets, codec and session per message in and out


@dataclass(frozen=True)
class Refusal:
    """Why new work is refused now (``reason``: memory, loop_lag, receive_lag, loop_busy or
    sessions), and when to ask again."""

    reason: str
    message: str
    retry_after_ms: int
    code: str = SERVER_BUSY

    @property
    def details(self) -> dict[str, JsonValue]:
        return {"retry_after_ms": self.retry_after_ms, "reason": self.reason}


@dataclass(frozen=True)
class Upgrade:
    """The admission key of a WebSocket upgrade admitted by the HTTP protocol, until the
    endpoint adopts it: the client's (host, port)."""

    client: tuple[str, int]


@dataclass(frozen=True)
class LoadLimits:
    """The thresholds (``ServerSettings``) and the calibrated costs, as fractions of one
    core: ``engine_costs`` of a session of each engine, ``session_cost`` of one whose engine
    is not known yet (the cheapest engine's)."""

    max_memory_mb: float
    max_lag_ms: float
    max_busy: float
    session_cost: float
    engine_costs: Mapping[str, float] = field(default_factory=dict)
    max_session_rate: float = 0.0


def calibrated_session_cost(ladders: Iterable[Sequence[RungEstimate]]) -> float:
    """The fraction of one core a session of real-time speech (one phoneme per
    ``PHONEME_S``, one message each) needs: the costliest model's default rung plus
    ``MESSAGE_OVERHEAD_MS`` per message."""
    per_phoneme_ms = max((ladder[0].per_phoneme_ms for ladder in ladders if ladder), default=0.0)
    return (per_phoneme_ms + MESSAGE_OVERHEAD_MS) / (1000.0 * PHONEME_S)


@dataclass
class OverloadPolicy:
    """The admission verdicts; ``now`` is monotonic time in seconds, a ``key`` names one
    session (its connection) from admission (``session_refusal``) to ``closed``."""

    limits: LoadLimits
    rng: random.Random = field(default_factory=random.Random)
    learned_cost: float = 0.0
    pending: dict[Hashable, float] = field(default_factory=dict)
    upgrades: dict[Upgrade, float] = field(default_factory=dict)
    priced: set[Hashable] = field(default_factory=set)
    streaming: set[Hashable] = field(default_factory=set)
    recent: deque[tuple[float, float]] = field(default_factory=deque)
    admitted: deque[float] = field(default_factory=deque)
    lock: threading.Lock = field(default_factory=threading.Lock)

    @property
    def session_cost(self) -> float:
        """The cost of a session whose engine is not known yet."""
        return max(self.learned_cost, self.limits.session_cost)

    def engine_cost(self, engine: str) -> float:
        """The cost of a session of loaded ``engine``: its calibrated cost, or the learned
        one when higher."""
        return max(self.learned_cost, self.limits.engine_costs[engine])

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

    def session_refusal(
        self, load: LoadSample, sessions: int, now: float, key: Hashable
    ) -> Refusal | None:
        """A refusal for a new session ``key`` with ``sessions`` open, or None after counting
        it as admitted and pending at ``now``."""
        with self.lock:
            self._learn(load, now)
            refusal = self._verdict(load, sessions, now)
            if refusal is None:
                self.admitted.append(now)
                if isinstance(key, Upgrade):
                    self.upgrades.pop(key, None)
                    self.upgrades[key] = now
                else:
                    self.pending[key] = now
            return refusal

    def verdict(self, load: LoadSample, sessions: int, now: float) -> Refusal | None:
        """The refusal ``session_refusal`` would give a new session now, counting and
        learning nothing (the learned cost moves once per session asked about, not per
        connection accepted): for the accept loop, which answers a refused upgrade before
        any protocol exists and leaves an admitted one to the HTTP protocol's
        ``session_refusal``."""
        with self.lock:
            return self._verdict(load, sessions, now)

    def _verdict(self, load: LoadSample, sessions: int, now: float) -> Refusal | None:
        refusal = self.request_refusal(load) or self._lag_refusal(load, sessions)
        refusal = refusal or self._rate_refusal(now)
        if refusal is None:
            refusal = self._busy_refusal(load, now, self.session_cost, "another session")
        return refusal

    def start_refusal(
        self, load: LoadSample, key: Hashable, engine: str, now: float
    ) -> Refusal | None:
        """A refusal for a ``start`` of ``engine`` by session ``key``: memory for every
        ``start``; for the session's first one of a loaded engine, also the loop's CPU at the
        engine's cost (the session is then priced and leaves the pending ones). A ``start``
        of an engine not loaded is refused later, as ``unknown_engine``, and prices
        nothing."""
        with self.lock:
            refusal = self.request_refusal(load)
            if refusal is not None or key in self.priced:
                return refusal
            if engine not in self.limits.engine_costs:
                return None
            self.pending.pop(key, None)
            cost = self.engine_cost(engine)
            refusal = self._busy_refusal(load, now, cost, f"a session of {engine}")
            if refusal is None:
                self.priced.add(key)
                self.recent.append((now, cost))
            return refusal

    def adopt(self, upgrade: Upgrade, key: Hashable) -> bool:
        """Session ``key`` is the upgrade the HTTP protocol admitted as ``upgrade``: pending
        under ``key`` from when the upgrade was admitted. False when no such upgrade is
        pending (admitted too long ago, or never)."""
        with self.lock:
            admitted = self.upgrades.pop(upgrade, None)
            if admitted is None:
                return False
            self.pending[key] = admitted
            return True

    def set_streaming(self, key: Hashable, streaming: bool) -> None:
        """Whether session ``key`` has a request active (the sessions the cost is learned
        from)."""
        with self.lock:
            if streaming:
                self.streaming.add(key)
            else:
                self.streaming.discard(key)

    def closed(self, key: Hashable) -> None:
        """Session ``key`` is gone."""
        with self.lock:
            self.pending.pop(key, None)
            self.priced.discard(key)
            self.streaming.discard(key)

    def shedding(self, load: LoadSample, sessions: int) -> bool:
        """Whether the loop lags so far behind (``SHED_FACTOR`` x ``max_lag_ms``, with
        ``LAG_FROM_SESSIONS`` sessions open) that even refusing a WebSocket with an
        ``error`` costs too much: new upgrades then get HTTP 503 before any WebSocket work."""
        lag_ms = max(load.lag_ms, load.receive_lag_ms)
        return sessions >= LAG_FROM_SESSIONS and lag_ms > SHED_FACTOR * self.limits.max_lag_ms

    def sessions_refusal(self, max_sessions: int) -> Refusal:
        return self._refusal(
            "sessions",
            f"the server is at its limit of {max_sessions} sessions",
            RETRY_AFTER_MS,
        )

    def unmeasured(self, now: float) -> float:
        """The cost the load window has not measured yet: every pending session whole, and
        the part of each recent first ``start`` after ``now - RECENT_S`` not yet in the
        window."""
        while self.recent and now - self.recent[0][0] >= RECENT_S:
            self.recent.popleft()
        while self.upgrades:  # in the order admitted: the stale ones come first
            oldest = next(iter(self.upgrades))
            if now - self.upgrades[oldest] < UPGRADE_TTL_S:
                break
            del self.upgrades[oldest]
        started = sum(cost * (1.0 - (now - at) / RECENT_S) for at, cost in self.recent)
        return started + (len(self.pending) + len(self.upgrades)) * self.session_cost

    def _rate_refusal(self, now: float) -> Refusal | None:
        """Past ``max_session_rate`` sessions a second, counted over the last
        ``RATE_WINDOW_S``."""
        rate = self.limits.max_session_rate
        while self.admitted and now - self.admitted[0] >= RATE_WINDOW_S:
            self.admitted.popleft()
        if not rate or len(self.admitted) < max(1.0, rate * RATE_WINDOW_S):
            return None
        what = f"new sessions arrive faster than {rate:g} a second"
        return self._refusal("admission_rate", what, RATE_RETRY_AFTER_MS)

    def _lag_refusal(self, load: LoadSample, sessions: int) -> Refusal | None:
        limit = self.limits.max_lag_ms
        if sessions < LAG_FROM_SESSIONS:
            return None
        if load.lag_ms > limit:
            what = f"the server's event loop lags {load.lag_ms:.0f} ms behind"
            return self._refusal("loop_lag", f"{what}, more than {limit:g} ms", RETRY_AFTER_MS)
        if load.receive_lag_ms > limit:
            what = f"client messages wait {load.receive_lag_ms:.0f} ms for the server"
            return self._refusal("receive_lag", f"{what}, more than {limit:g} ms", RETRY_AFTER_MS)
        return None

    def _busy_refusal(self, load: LoadSample, now: float, cost: float, what: str) -> Refusal | None:
        projected = load.loop_busy + self.unmeasured(now) + cost
        if projected <= self.limits.max_busy:
            return None
        return self._refusal(
            "loop_busy",
            f"{what} would make the server's event loop {100 * projected:.0f} % busy, more "
            f"than {100 * self.limits.max_busy:.0f} %",
            RETRY_AFTER_MS,
        )

    def _learn(self, load: LoadSample, now: float) -> None:
        self.unmeasured(now)
        measured = len(self.streaming) - sum(1.0 - (now - at) / RECENT_S for at, _ in self.recent)
        if measured < LEARN_FROM_SESSIONS:
            return
        observed = load.loop_busy / measured
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

    def session_refusal(self, sessions: int, key: Hashable) -> Refusal | None:
        return self.policy.session_refusal(self.monitor.sample(), sessions, time.monotonic(), key)

    def verdict(self, sessions: int) -> Refusal | None:
        """What a new session would be told now, counting nothing (``OverloadPolicy.verdict``)."""
        return self.policy.verdict(self.monitor.sample(), sessions, time.monotonic())

    def upgrade_refusal(self, sessions: int, upgrade: Upgrade) -> Refusal | None:
        """For a WebSocket upgrade, from the HTTP protocol: admitted, it is pending as
        ``upgrade`` until the endpoint ``adopt``s it."""
        return self.session_refusal(sessions, upgrade)

    def adopt(self, upgrade: Upgrade, key: Hashable) -> bool:
        return self.policy.adopt(upgrade, key)

    def start_refusal(self, key: Hashable, engine: str) -> Refusal | None:
        """For a session's ``start``; safe from the synthesis pool's threads, where a
        session may handle it."""
        return self.policy.start_refusal(self.monitor.sample(), key, engine, time.monotonic())

    def shedding(self, sessions: int) -> bool:
        return self.policy.shedding(self.monitor.sample(), sessions)

    def request_refusal(self, held_mb: float = 0.0) -> Refusal | None:
        """Memory only, from the monitor's latest figure plus ``held_mb`` the caller knows the
        process holds and the figure may not show yet: safe from the synthesis pool's
        threads, where a session may handle its ``start``."""
        return self.policy.request_refusal(LoadSample(rss_mb=self.monitor.rss_mb + held_mb))


def memory_ceiling_mb(settings: ServerSettings) -> float:
    """``LIPSTREAM_MAX_MEMORY_MB``, or when 0, ``AUTO_MEMORY_SHARE`` of the memory the
    process may use (``load.machine_memory_mb``) divided among the workers."""
    if settings.max_memory_mb:
        return float(settings.max_memory_mb)
    return AUTO_MEMORY_SHARE * machine_memory_mb() / settings.workers


def engine_costs(catalog: Catalog) -> dict[str, float]:
    """Each loaded engine's calibrated session cost (``calibrated_session_cost`` over its
    models)."""
    ladders: dict[str, list[Sequence[RungEstimate]]] = {}
    for model in catalog.registry.models.values():
        facts = catalog.facts.get(id(model))
        if facts is not None:
            ladders.setdefault(model.manifest.engine, []).append(facts.ladder)
    return {engine: calibrated_session_cost(each) for engine, each in ladders.items()}


def overload_for(
    settings: ServerSettings,
    catalog: Catalog,
    on_sample: Callable[[LoadSample], None] | None = None,
) -> Overload:
    """The admission of a server with ``settings`` serving ``catalog``'s models, its monitor
    (which passes each sample to ``on_sample``) not yet started."""
    costs = engine_costs(catalog)
    limits = LoadLimits(
        memory_ceiling_mb(settings),
        settings.max_loop_lag_ms,
        settings.max_loop_busy,
        min(costs.values(), default=calibrated_session_cost([])),
        costs,
        settings.max_session_rate,
    )
    return Overload(OverloadPolicy(limits), LoadMonitor(on_sample=on_sample))
