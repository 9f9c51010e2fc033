"""Outgoing messages and the send-side clock of each request.

Sketch: the session (sans I/O) returns ``Outgoing`` items; the connection's
writer calls ``stamp(now)`` right before sending one. Stamping a frames block
records its lag: ``now`` minus the receipt time of the input that covers the
block's first frame (later rows were covered no earlier, so the first row
has the block's largest lag). Stamping a ``done`` fills its timing stats
from the request's clock. After ``start``, only the writer touches a clock,
so a session running in the synthesis thread pool never races it.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from lipstream_client import Done, DoneStats, Frames, ServerMessage

_MS = 1000.0


@dataclass
class RequestClock:
    """When a request started (monotonic s), its budget, and what sending has measured."""

    engine: str
    started_at: float
    budget_ms: float | None
    first_sent_at: float | None = None
    max_lag_s: float | None = None
    speech_s: float | None = None
    """Seconds spent speaking the request's ``text`` (None: it had none)."""

    def spoke(self, seconds: float) -> None:
        """Record ``seconds`` of speech synthesis for one ``text`` message."""
        self.speech_s = (self.speech_s or 0.0) + max(0.0, seconds)

    def frames_sent(self, covered_at: float, now: float) -> tuple[float, float | None]:
        """Record a block sent at ``now``; (its lag, the first-frame latency if it is the
        request's first block) in seconds."""
        first_latency = None
        if self.first_sent_at is None:
            self.first_sent_at = now
            first_latency = max(0.0, now - self.started_at)
        lag = max(0.0, now - covered_at)
        self.max_lag_s = lag if self.max_lag_s is None else max(self.max_lag_s, lag)
        return lag, first_latency

    def final_stats(self, stats: DoneStats) -> DoneStats:
        """``stats`` (frames, engine) completed with latency, lag, the budget verdict and the
        speech synthesis time."""
        latency = (
            None
            if self.first_sent_at is None
            else _MS * max(0.0, self.first_sent_at - self.started_at)
        )
        lag_ms = None if self.max_lag_s is None else _MS * self.max_lag_s
        met = None if self.budget_ms is None else (lag_ms is None or lag_ms <= self.budget_ms)
        speech_ms = None if self.speech_s is None else _MS * self.speech_s
        return replace(
            stats,
            first_frame_latency_ms=latency,
            max_lag_ms=lag_ms,
            budget_met=met,
            speech_synthesis_ms=speech_ms,
        )


@dataclass(slots=True)
class Stamped:
    """A message as sent, with what sending it measured (seconds)."""

    message: ServerMessage
    engine: str | None = None
    lag_s: float | None = None
    first_frame_latency_s: float | None = None


@dataclass(slots=True)
class Outgoing:
    """A server message on its way out.

    ``clock`` is the request's clock (None for connection-level messages);
    ``covered_at`` is, for frames, when the input covering the first row
    was received.
    """

    message: ServerMessage
    clock: RequestClock | None = None
    covered_at: float | None = None

    def stamp(self, now: float) -> Stamped:
        """The message to send at ``now``, recording its timing on the request's clock."""
        message, clock = self.message, self.clock
        if clock is None:
            return Stamped(message)
        if isinstance(message, Frames):
            covered_at = now if self.covered_at is None else self.covered_at
            lag, first_latency = clock.frames_sent(covered_at, now)
            return Stamped(message, clock.engine, lag, first_latency)
        if isinstance(message, Done):
            return Stamped(replace(message, stats=clock.final_stats(message.stats)), clock.engine)
        return Stamped(message, clock.engine)
