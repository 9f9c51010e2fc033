"""What one load-generating process runs for one clip length: sessions, pacing, measuring.

Sketch: a ``ClipPlan`` (the same in every process) holds the clip's phoneme
spans, the seeded start delays and the run's deadline; a process gets a
share of the request indices and of the concurrent sessions. Each session
is one ``AsyncClient`` connection that runs its requests one after another:
wait the request's start delay, send ``start``, send phoneme k when the
utterance clock (started when ``start`` was sent) reaches its start time
minus ``lead_ms``, then ``end``, and wait for ``done``. The client's message
tap timestamps every server message as it comes off the socket; for a
frames block it records the block's lag (arrival minus the scheduled time
of its first frame, ``start`` sent + first_frame / fps) and its length, and
``ClipShare.frame_lags_ms`` expands them afterwards (row r of a block is
scheduled r / fps later, so its lag is r / fps smaller). Keeping two numbers
per block instead of one per frame, and dropping frames with ``poll()``
instead of a reader task per request, keeps the load generator's own CPU
low: it shares the machine with the server it measures.

The optional probe measures the first-frame latency of a whole utterance
sent at once (``probe_phonemes`` phonemes in one ``phonemes`` message, as
a TTS that has synthesized a sentence sends it) on one extra connection,
one request after another, for as long as the load runs.

A session the server refuses for load (``server_busy``, 1013, or HTTP 503 to its
upgrade while the server sheds load or holds its cap of connections), or whose request
alone it refuses (``server_busy`` answering a ``start``), waits the
``retry_after_ms`` or ``Retry-After`` it was given and tries again, as a client
following the protocol does, up to ``BUSY_RETRIES`` times while its clip still fits
before the deadline; ``RequestRecord.busy_retries`` counts them. Without this, a capacity
step that opens its sessions within a second meets load-based admission,
which admits a burst of new sessions at the cost of the dearest rung the server
holds, before it measures any load.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import time
from array import array
from collections.abc import Callable, Coroutine, Sequence
from dataclasses import dataclass, field
from typing import Any, TypeVar

from lipstream_client import Done, Frames, Ready, ServerMessage
from lipstream_client.client import AsyncClient, Stream
from lipstream_client.exceptions import (
    ConnectionClosed,
    HandshakeRejected,
    LipstreamClientError,
    LipstreamServerError,
    ServerBusy,
    retry_delay_s,
)
from lipstream_client.messages import Encoding

REQUEST_SLACK_S = 15.0
BUSY_RETRIES = 8
PROBE_PAUSE_S = 0.1
_MS = 1000.0
T = TypeVar("T")
Span = tuple[str, float, float]


@dataclass(frozen=True)
class ClipPlan:
    """What every process needs to run one clip length."""

    url: str
    engine: str
    character: str
    encoding: Encoding
    token: str | None
    fps: float
    lead_ms: float
    latency_budget_ms: float | None
    spans: tuple[Span, ...]
    jitter_s: tuple[float, ...]
    deadline: float
    probe_phonemes: int = 0
    probe_spans: tuple[Span, ...] = ()

    @property
    def clip_s(self) -> float:
        return self.spans[-1][2]


@dataclass
class RequestRecord:
    """The outcome of one request; latencies in ms, None when not reached."""

    error: str | None = None
    first_packet_ms: float | None = None
    first_frame_ms: float | None = None
    fps: float | None = None
    frames: int = 0
    server_max_lag_ms: float | None = None
    send_slip_ms: list[float] = field(default_factory=list)
    busy_retries: int = 0
    streaming_s: list[float] | None = None

    @property
    def streaming_span(self) -> tuple[float, float] | None:
        """(ready, done) on the machine's monotonic clock (s), when the request got both."""
        return None if self.streaming_s is None else (self.streaming_s[0], self.streaming_s[1])


@dataclass
class ClipShare:
    """What one process measured: its requests, its frames blocks (lag of the first frame
    in ms, frame count), its probe latencies (ms) and its CPU seconds."""

    records: list[RequestRecord] = field(default_factory=list)
    block_lag_ms: array[float] = field(default_factory=lambda: array("d"))
    block_frames: array[int] = field(default_factory=lambda: array("q"))
    probe_ms: list[float] = field(default_factory=list)
    probe_errors: list[str] = field(default_factory=list)
    cpu_s: float = 0.0
    session_spans: list[tuple[float, float]] = field(default_factory=list)

    def extend(self, other: ClipShare) -> None:
        self.records.extend(other.records)
        self.session_spans.extend(other.session_spans)
        self.block_lag_ms.extend(other.block_lag_ms)
        self.block_frames.extend(other.block_frames)
        self.probe_ms.extend(other.probe_ms)
        self.probe_errors.extend(other.probe_errors)
        self.cpu_s += other.cpu_s

    def frame_lags_ms(self, fps: float) -> array[float]:
        """The lag of every frame (ms): row r of a block arrived with its first frame but
        was scheduled r / fps later."""
        step = _MS / fps
        lags: array[float] = array("d")
        for first, count in zip(self.block_lag_ms, self.block_frames):
            lags.extend(first - row * step for row in range(count))
        return lags


@dataclass
class _Trace:
    """What one request saw, filled in by the client's message tap (perf_counter s)."""

    sent_at: float
    ready_at: float | None = None
    first_frames_at: float | None = None
    done_at: float | None = None
    frames: int = 0


class _Session:
    """One concurrent stream: a connection that runs requests one after another."""

    def __init__(self, plan: ClipPlan, share: ClipShare, pending: list[int]) -> None:
        self.plan = plan
        self.share = share
        self.pending = pending
        self.traces: dict[str, _Trace] = {}
        self.client: AsyncClient | None = None
        self._ids = itertools.count(1)
        self._held: tuple[float, float] | None = None  # first ready, last done

    def on_message(self, message: ServerMessage, received_at: float) -> None:
        trace = self.traces.get(message.id or "")
        if trace is None:
            return
        if isinstance(message, Frames):
            if trace.first_frames_at is None:
                trace.first_frames_at = received_at
            scheduled = trace.sent_at + message.first_frame / self.plan.fps
            self.share.block_lag_ms.append((received_at - scheduled) * _MS)
            self.share.block_frames.append(message.n_frames)
            trace.frames += message.n_frames
        elif isinstance(message, Ready) and trace.ready_at is None:
            trace.ready_at = received_at
        elif isinstance(message, Done):
            trace.done_at = received_at

    async def work(self) -> None:
        try:
            while self.pending:
                index = self.pending.pop()
                if time.perf_counter() + self.plan.clip_s > self.plan.deadline:
                    self.share.records.append(RequestRecord(error="deadline"))
                    continue
                await asyncio.sleep(self.plan.jitter_s[index])
                record = await self._request()
                self.share.records.append(record)
                if (span := record.streaming_span) is not None:
                    self._held = span if self._held is None else (self._held[0], span[1])
        finally:
            if self.client is not None:
                await self.client.close()
            if self._held is not None:
                self.share.session_spans.append(self._held)

    async def _connected(self) -> AsyncClient:
        if self.client is None or self.client.closed is not None:
            plan = self.plan
            self.client = AsyncClient(
                plan.url, plan.encoding, plan.token, on_message=self.on_message
            )
            await self.client.connect()
        return self.client

    async def _request(self) -> RequestRecord:
        record = RequestRecord()
        for attempt in range(BUSY_RETRIES + 1):
            busy = await self._attempt(record)
            delay = retry_delay_s(busy, attempt) if busy is not None else 0.0
            if busy is None or attempt == BUSY_RETRIES or not self._fits(delay):
                return record
            record.error = None
            record.busy_retries += 1
            if not isinstance(busy, LipstreamServerError):
                await self._drop_connection()
            await asyncio.sleep(delay)
        return record

    def _fits(self, delay_s: float) -> bool:
        return time.perf_counter() + delay_s + self.plan.clip_s <= self.plan.deadline

    async def _attempt(self, record: RequestRecord) -> LipstreamClientError | None:
        """One try of the request into ``record``; the refusal, when the server was busy: of
        the connection (``ServerBusy``, a retryable ``HandshakeRejected``) or of the request
        alone (a retryable ``LipstreamServerError``, such as ``server_busy`` at a ``start``
        whose engine costs more than the load leaves room for; the connection stays)."""
        try:
            client = await self._connected()
            await asyncio.wait_for(self._stream(client, record), self.plan.clip_s + REQUEST_SLACK_S)
        except LipstreamServerError as error:
            record.error = error.code
            if error.retryable and error.id is not None:
                return error
        except ServerBusy as busy:
            record.error = refusal_code(busy)
            return busy
        except ConnectionClosed as error:
            record.error = refusal_code(error)
        except HandshakeRejected as error:
            record.error = refusal_code(error)
            if error.retryable:
                return error
        except TimeoutError:
            record.error = "timeout"
            await self._drop_connection()
        except (OSError, LipstreamClientError) as error:
            record.error = type(error).__name__
            await self._drop_connection()
        return None

    async def _drop_connection(self) -> None:
        if self.client is not None:
            await self.client.close()
            self.client = None

    async def _stream(self, client: AsyncClient, record: RequestRecord) -> None:
        plan = self.plan
        request_id = f"load-{next(self._ids)}"
        # Registered before sending: on loopback, ready can beat start() returning.
        trace = _Trace(time.perf_counter())
        self.traces[request_id] = trace
        try:
            stream = await client.start(
                plan.engine,
                plan.character,
                id=request_id,
                fps=plan.fps,
                latency_budget_ms=plan.latency_budget_ms,
            )
            await self._pace(stream, trace.sent_at, record)
            await stream.end()
            done = await stream.done()
            stream.poll()
        finally:
            self.traces.pop(request_id, None)
        _fill(record, trace, done)

    async def _pace(self, stream: Stream, origin: float, record: RequestRecord) -> None:
        """Send each phoneme when it is due; a phoneme due before ``start`` was sent (a lead
        longer than its start time) goes at once and counts no slip."""
        lead_s = self.plan.lead_ms / _MS
        for label, start, end in self.plan.spans:
            due = max(origin, origin + start - lead_s)
            delay = due - time.perf_counter()
            if delay > 0:
                await asyncio.sleep(delay)
            record.send_slip_ms.append(max(0.0, time.perf_counter() - due) * _MS)
            await stream.send_phonemes([(label, start, end)])
            stream.poll()  # frames were measured by the tap; drop them


def _fill(record: RequestRecord, trace: _Trace, done: Done) -> None:
    if trace.ready_at is not None:
        record.first_packet_ms = (trace.ready_at - trace.sent_at) * _MS
    if trace.first_frames_at is not None:
        record.first_frame_ms = (trace.first_frames_at - trace.sent_at) * _MS
        if trace.done_at is not None:
            span = trace.done_at - trace.first_frames_at
            record.fps = trace.frames / span if span > 0 else None
    record.frames = trace.frames
    record.server_max_lag_ms = done.stats.max_lag_ms
    if trace.ready_at is not None and trace.done_at is not None:
        # one clock for every worker process: perf_counter's origin is per process
        to_monotonic = time.monotonic() - time.perf_counter()
        record.streaming_s = [trace.ready_at + to_monotonic, trace.done_at + to_monotonic]


async def probe_first_frames(plan: ClipPlan, share: ClipShare, running: Callable[[], bool]) -> None:
    """While ``running()``, send whole ``probe_phonemes``-phoneme requests one after
    another on one connection and record each one's first-frame latency (ms): from
    sending ``start`` to receiving the first frames. It starts once every start delay of
    the load has passed, so it measures at full concurrency. Refused for load, it
    reconnects after the time it was given, as the sessions do; refusals are not
    latencies, so they are not recorded."""
    items = plan.probe_spans[: plan.probe_phonemes]
    await asyncio.sleep(max(plan.jitter_s, default=0.0))
    for attempt in itertools.count():
        try:
            async with AsyncClient(plan.url, plan.encoding, plan.token) as client:
                await _probe_requests(plan, share, client, items, running)
            return
        except (ServerBusy, HandshakeRejected) as refused:
            if not refused.retryable or not _probing(plan, running):
                share.probe_errors.append(refusal_code(refused))
                return
            await asyncio.sleep(retry_delay_s(refused, attempt))
        except (OSError, LipstreamClientError) as error:
            share.probe_errors.append(type(error).__name__)
            return


def _probing(plan: ClipPlan, running: Callable[[], bool]) -> bool:
    return running() and time.perf_counter() < plan.deadline


def refusal_code(refused: ConnectionClosed | HandshakeRejected) -> str:
    """The error key of a closed or refused connection: the server's code, ``closed_<code>``
    for a close without one, ``http_<status>`` for an upgrade refused without an error body."""
    if isinstance(refused, HandshakeRejected):
        return refused.error.code if refused.error else f"http_{refused.status}"
    return refused.error.code if refused.error else f"closed_{refused.code}"


async def _probe_requests(
    plan: ClipPlan,
    share: ClipShare,
    client: AsyncClient,
    items: Sequence[Span],
    running: Callable[[], bool],
) -> None:
    while _probing(plan, running):
        try:
            share.probe_ms.append(await _probe_once(plan, client, items))
        except LipstreamServerError as error:
            share.probe_errors.append(error.code)
        await asyncio.sleep(PROBE_PAUSE_S)


async def _probe_once(plan: ClipPlan, client: AsyncClient, items: Sequence[Span]) -> float:
    sent_at = time.perf_counter()
    stream = await client.start(
        plan.engine, plan.character, fps=plan.fps, latency_budget_ms=plan.latency_budget_ms
    )
    await stream.send_phonemes(items)
    await stream.end()
    first = await asyncio.wait_for(stream.next_block(), plan.clip_s + REQUEST_SLACK_S)
    latency = (time.perf_counter() - sent_at) * _MS
    await stream.done()
    stream.poll()
    if first is None:
        raise LipstreamClientError("a probe request ended without frames")
    return latency


async def run_share(
    plan: ClipPlan,
    indices: Sequence[int],
    sessions: int,
    probe: bool,
    others_running: Callable[[], bool] | None = None,
) -> ClipShare:
    """Run ``sessions`` concurrent sessions over the requests ``indices`` (claimed in
    order), and the probe if asked, for as long as this share's sessions or
    ``others_running()`` (other processes' load) go on. CPU time is this process's."""
    share = ClipShare()
    cpu_began = time.process_time()
    pending = list(reversed(indices))
    load = [asyncio.create_task(_Session(plan, share, pending).work()) for _ in range(sessions)]

    def running() -> bool:
        return any(not task.done() for task in load) or (
            others_running is not None and others_running()
        )

    probing = [probe_first_frames(plan, share, running)] if probe and plan.probe_phonemes else []
    await asyncio.gather(*load, *probing)
    share.cpu_s = time.process_time() - cpu_began
    return share


def run_coroutine(coroutine: Coroutine[Any, Any, T]) -> T:
    """Run ``coroutine`` on a fresh event loop: uvloop's when it is installed, as uvicorn
    does, else asyncio's."""
    with asyncio.Runner(loop_factory=event_loop_factory()) as runner:
        return runner.run(coroutine)


def event_loop_factory() -> Callable[[], asyncio.AbstractEventLoop] | None:
    """uvloop's loop factory if uvloop is installed, else None (asyncio's default)."""
    with contextlib.suppress(ImportError):
        import uvloop

        factory: Callable[[], asyncio.AbstractEventLoop] = uvloop.new_event_loop
        return factory
    return None


def event_loop_name() -> str:
    return "asyncio" if event_loop_factory() is None else "uvloop"
