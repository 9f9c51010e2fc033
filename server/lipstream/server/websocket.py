"""The WebSocket endpoint ``/v1/stream``: the only asynchronous part of streaming.

Sketch: a handshake is checked before anything is allocated. The offered
subprotocols pick the encoding (an offer naming none that we speak is
refused with HTTP 403); then come the Origin allow-list, the bearer token,
the drain, the measured load (``overload``: memory, event-loop lag and busy
time) and the session cap. A refused connection is accepted only to receive
an ``error`` (for ``server_busy`` with ``details.retry_after_ms``) and its
close code. An admitted connection is one task that takes one message at a
time: rate limit (token bucket), decode (size-limited, sans I/O), then
``Session.handle``, inline when the engine's estimate of its work is below
``inline_work_ms``, in the synthesis thread pool up to ``heavy_work_ms``,
and in the heavy lane (a pool of its own, ``lanes.FairLane``, taking turns
between connections) above (with its frames encoded there too), and a ``text``
message in the speech lane, apart from both, so the event loop never waits on
a long synthesis, ordinary sessions never queue behind a costly one, and
speech never queues behind a search; answers of more than
``JSON_INLINE_VALUES`` JSON numbers are encoded in the pool as well (in the
heavy lane above ``JSON_HEAVY_VALUES``). While work runs in the pool the
connection keeps receiving (``read_ahead``): the socket is read and pings
answered, a ``cancel`` stops its request's work at once
(``Session.stop_work``), so do phonemes that take their request past its
engine's cap (``Session.check_queued``), a closed socket stops all of it,
and the messages read wait, in order, for their turn. Then the task stamps
and sends the answers itself. Sending from the same task, rather than
handing each answer to a writer task, saves a task switch and a queue round
trip per message, the largest cost left once the engine is fast. A send
waits only when the client's socket buffers are full; the connection then
reads nothing more from that client (backpressure), and a send that misses
its deadline (``deadline.SendDeadline``) closes the connection with 1008
``slow_consumer``: a client that stops reading would otherwise pin
``await send`` forever. Frames are never dropped silently. A connection
with no message and no active request for ``idle_timeout_s`` closes with
1000; a request with no message for ``request_timeout_s`` ends with
``request_timeout`` (a per-connection timer, ``deadline.LaterDeadline``, ends the
wait for the next message at the session's ``next_expiry``); a draining one closes
with 1001 as soon as its requests are done.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import Executor
from typing import Any, TypeAlias, TypeVar

from starlette.websockets import WebSocket, WebSocketDisconnect

from lipstream_client import (
    ERROR_CODES,
    Cancel,
    CloseCode,
    Done,
    Encoding,
    ErrorMessage,
    Frames,
    Phonemes,
    ProtocolError,
    Text,
    decode,
    encode,
    encoding_for_subprotocol,
    select_subprotocol,
)
from lipstream_client.errors import (
    IDLE_TIMEOUT,
    ORIGIN_NOT_ALLOWED,
    RATE_LIMITED,
    SHUTTING_DOWN,
    SLOW_CONSUMER,
    STARTING,
    UNAUTHORIZED,
)
from lipstream_client.messages import JsonValue

from .admission import TokenBucket, bearer_token, origin_allowed, token_accepted
from .deadline import LaterDeadline, SendDeadline
from .frames_wire import MessageEncoder
from .outgoing import Outgoing
from .overload import Upgrade
from .read_ahead import DISCONNECT, ReadAhead, Received
from .read_window import ARRIVED_AT
from .session import InputMessage, Session
from .startup import Startup
from .state import ServerState

logger = logging.getLogger("lipstream.server")

UNSUPPORTED_SUBPROTOCOL = "unsupported_subprotocol"
CLOSE_DEADLINE_S = 1.0
STARTING_SEND_S = 10.0
_IDLE = object()
_WAKE = object()
_PEER_GONE = (WebSocketDisconnect, RuntimeError, OSError)
JSON_INLINE_VALUES = 512  # about 4 ms of JSON encoding: more goes to the pool
JSON_HEAVY_VALUES = 65_536  # about 0.5 s of JSON encoding: the heavy lane's
Payload: TypeAlias = bytes | str
Answers: TypeAlias = tuple[list[Outgoing], list[Payload | None]]
T = TypeVar("T")


async def stream_endpoint(websocket: WebSocket) -> None:
    """Serve one WebSocket connection of the lipstream protocol."""
    startup: Startup = websocket.state.startup
    offered: list[str] = list(websocket.scope.get("subprotocols") or [])
    subprotocol = select_subprotocol(offered)
    encoding = encoding_for_subprotocol(subprotocol)
    state = startup.server
    if state is None:
        await _refuse_while_starting(websocket, encoding, subprotocol, startup)
        return
    if encoding is None or (offered and subprotocol is None):
        state.metrics.refused.labels(UNSUPPORTED_SUBPROTOCOL).inc()
        await websocket.close(code=CloseCode.POLICY_VIOLATION)
        return
    refusal = _refusal(websocket, state)
    connection = Connection(websocket, encoding, state)
    details: dict[str, JsonValue] | None = None
    admitted = _adopt_upgrade(websocket, state, connection)
    if refusal is None:
        busy = None
        if not admitted:
            busy = state.overload.session_refusal(len(state.lifecycle.connections), connection)
        if busy is None and not state.lifecycle.admit(connection):
            busy = state.overload.policy.sessions_refusal(state.settings.max_sessions)
        if busy is not None:
            state.metrics.busy_refusals.labels(busy.reason).inc()
            refusal, details = (busy.code, busy.message), busy.details
    try:
        await websocket.accept(subprotocol=subprotocol)
        if refusal is not None:
            state.metrics.refused.labels(refusal[0]).inc()
            await _refuse(websocket, encoding, refusal[0], refusal[1], state, details)
            return
        state.metrics.sessions.inc()
        try:
            await connection.run()
        finally:
            state.metrics.sessions.dec()
    finally:
        state.lifecycle.release(connection)
        state.overload.policy.closed(connection)


def _adopt_upgrade(websocket: WebSocket, state: ServerState, connection: Connection) -> bool:
    """Whether the HTTP protocol admitted this connection's upgrade for load (``handshake``);
    it is then pending under ``connection``."""
    client = websocket.scope.get("client")
    if client is None:
        return False
    return state.overload.adopt(Upgrade((client[0], client[1])), connection)


def _refusal(websocket: WebSocket, state: ServerState) -> tuple[str, str] | None:
    settings = state.settings
    if not origin_allowed(websocket.headers.get("origin"), settings.allowed_origins):
        return ORIGIN_NOT_ALLOWED, "this Origin may not use the server"
    token = bearer_token(websocket.headers.get("authorization"), websocket.scope["query_string"])
    if not token_accepted(token, settings.auth_tokens):
        return UNAUTHORIZED, (
            "a valid bearer token is required (Authorization: Bearer <token>, "
            "or ?access_token=<token>)"
        )
    if state.lifecycle.draining:
        return SHUTTING_DOWN, "the server is shutting down; connect to another instance"
    return None


async def _refuse_while_starting(
    websocket: WebSocket, encoding: Encoding | None, subprotocol: str | None, startup: Startup
) -> None:
    """Accept, send ``starting`` (naming the phase) and close with 1013; a connection that
    offered no protocol this server speaks is closed with 1008 as when ready."""
    if encoding is None:
        await websocket.close(code=CloseCode.POLICY_VIOLATION)
        return
    error = startup.not_ready()
    await websocket.accept(subprotocol=subprotocol)
    details: dict[str, JsonValue] = {"phase": error.where}
    await _refuse(websocket, encoding, STARTING, error.message, STARTING_SEND_S, details)


async def _refuse(
    websocket: WebSocket,
    encoding: Encoding,
    code: str,
    message: str,
    state: ServerState | float,
    details: dict[str, JsonValue] | None = None,
) -> None:
    """Send ``code`` and close; ``state`` gives the send timeout (or is it, in seconds)."""
    error = ErrorMessage(code, message, None, True, details or {})
    payload = encode(error, encoding, validate=False)
    close_code = ERROR_CODES[code].close_code or CloseCode.POLICY_VIOLATION
    timeout_s = state if isinstance(state, float) else state.settings.send_timeout_s
    try:
        async with asyncio.timeout(timeout_s):
            await _send(websocket, payload)
            await websocket.close(code=close_code, reason=code)
    except (TimeoutError, *_PEER_GONE):
        return


async def _send(websocket: WebSocket, payload: bytes | str) -> None:
    if isinstance(payload, bytes):
        await websocket.send_bytes(payload)
    else:
        await websocket.send_text(payload)


class Connection:
    """One admitted WebSocket: a task that reads, handles and sends, and the session state."""

    def __init__(self, websocket: WebSocket, encoding: Encoding, state: ServerState) -> None:
        self.websocket = websocket
        self.encoding = encoding
        self.state = state
        self.settings = state.settings
        self.metrics = state.metrics
        self.tally = state.metrics.tally
        self.encode = MessageEncoder(encoding)
        self.session = Session(
            state.catalog,
            state.session_limits,
            lambda engine: state.overload.start_refusal(self, engine),
            state.input_ledger,
        )
        self.bucket = TokenBucket(
            self.settings.message_rate, self.settings.message_burst, time.monotonic()
        )
        self.loop = asyncio.get_running_loop()
        self.deadline = SendDeadline(self.loop, self.settings.send_timeout_s)
        self.expiry = LaterDeadline(self.loop, self.session.next_expiry, self._wake)
        self.finished = False
        self.aborted = False
        self._task: asyncio.Task[Any] | None = None
        self._receiving = False
        self._woken = False
        self._active = 0
        self._stopped = 0
        self.read_ahead = ReadAhead(self.settings.max_message_bytes)
        self._receive_task: asyncio.Task[Received] | None = None
        self._peer_gone = False
        self._first_frame: dict[str, Any] = {}

    # ---- lifecycle hooks (Drainable) ------------------------------------------------------

    def drain(self) -> None:
        self.session.begin_drain()
        self._wake()

    def abort(self) -> None:
        self.aborted = True
        self.session.stop_all_work()
        self._wake()

    def _wake(self) -> None:
        """Interrupt a wait for the client's next message, so the loop sees the new state;
        at any other moment the loop checks it before it waits again."""
        if self._receiving and self._task is not None and not self._woken:
            self._woken = True
            self._task.cancel()

    # ---- run ------------------------------------------------------------------------------

    async def run(self) -> None:
        self._task = asyncio.current_task()
        try:
            await self._serve()
        except Exception:
            logger.exception("unexpected fault in a WebSocket connection")
            if not self.finished:
                await self._close(
                    CloseCode.INTERNAL_ERROR, "internal_error", "an unexpected server fault"
                )
        finally:
            self.deadline.disarm()
            self.expiry.disarm()
            if self._receive_task is not None:
                self._receive_task.cancel()
            self.session.close()
            self._track_active()
            self.metrics.fold_tally()

    async def _serve(self) -> None:
        settings = self.settings
        while not self.finished:
            if self.aborted or (self.session.draining and self.session.active_requests == 0):
                await self._close(
                    CloseCode.GOING_AWAY,
                    SHUTTING_DOWN,
                    "the server is shutting down; reconnect to another instance",
                )
                return
            received = await self._next_event()
            if received is _WAKE:
                if not await self._send_all(self._expired(time.monotonic())):
                    return
                continue
            if received is _IDLE:
                await self._close(
                    CloseCode.NORMAL,
                    IDLE_TIMEOUT,
                    f"no message and no active request for {settings.idle_timeout_s:g} s",
                )
                return
            assert isinstance(received, Received)
            if received.event["type"] == "websocket.disconnect":
                return
            expired = self._expired(received.at)
            if expired and not await self._send_all(expired):
                return
            if not self.bucket.take(received.at):
                await self._close(
                    CloseCode.POLICY_VIOLATION,
                    RATE_LIMITED,
                    f"more than {settings.message_rate:g} messages per second "
                    f"(bursts of {settings.message_burst})",
                )
                return
            decoded = received.decoded
            if decoded is None:
                decoded = self._decode(received.event)
            self._count(decoded)
            outgoing, payloads = await self._handle(decoded, received.at)
            self._track_active()
            if not await self._send_all(outgoing, payloads):
                return
            ending = _connection_ending(outgoing)
            if ending is not None:
                await self._close(*ending)
                return

    def _count(self, decoded: InputMessage) -> None:
        self.tally.message("invalid" if isinstance(decoded, ProtocolError) else decoded.type)

    def _decode(self, event: Mapping[str, Any]) -> InputMessage:
        payload = event["bytes"] if event.get("bytes") is not None else event.get("text", "")
        return decode(
            payload, self.encoding, max_size=self.settings.max_message_bytes, sender="client"
        )

    def _expired(self, now: float) -> list[Outgoing]:
        """The errors of the requests that had no message for the request timeout by
        ``now`` (``Session.expire``)."""
        expired = self.session.expire(now)
        if expired:
            self._track_active()
        return expired

    async def _next_event(self) -> object:
        """The client's next message (those read ahead first); ``_IDLE`` after
        ``idle_timeout_s`` without one while no request is active, ``_WAKE`` when ``_wake``
        interrupted the wait or an active request's timeout (``Session.next_expiry``) came
        first."""
        ahead = self.read_ahead.pop()
        if ahead is not None:
            return ahead
        timeout: float | None = self.settings.idle_timeout_s
        if self.session.active_requests:
            timeout = None  # the request timeout's own timer (``expiry``) wakes the wait
            expiry = self.session.next_expiry()
            if expiry is not None:
                if expiry <= time.monotonic():
                    return _WAKE
                self.expiry.arm(expiry)
        self._receiving = True
        try:
            if self._receive_task is not None:
                done, _ = await asyncio.wait({self._receive_task}, timeout=timeout)
                if not done:
                    return _IDLE
                task, self._receive_task = self._receive_task, None
                return task.result()
            if timeout is None:
                return await self._receive()
            async with asyncio.timeout(timeout):
                return await self._receive()
        except TimeoutError:
            return _IDLE
        except asyncio.CancelledError:
            if not self._woken or self._task is None or self._task.uncancel():
                raise
            return _WAKE
        finally:
            self._receiving = False
            self._woken = False

    async def _receive(self) -> Received:
        """The next ASGI event, received when its bytes reached the process (``ARRIVED_AT``,
        from the transport), with its wait for the app recorded as the receive lag."""
        try:
            event: Mapping[str, Any] = await self.websocket.receive()
        except _PEER_GONE:
            event = DISCONNECT
        now = time.monotonic()
        arrived = event.get(ARRIVED_AT)
        if not isinstance(arrived, float) or arrived > now:
            return Received(event, now)
        self.state.overload.monitor.observe_receive(now - arrived)
        self.tally.receive_lag.observe(now - arrived)
        return Received(event, arrived)

    async def _handle(self, decoded: InputMessage, now: float) -> Answers:
        """The answers to ``decoded``, with the payloads encoded in the pool (None: encode
        when sending)."""
        work_ms = self.session.estimated_work_ms(decoded)
        if work_ms > self.settings.inline_work_ms:
            if isinstance(decoded, Text):
                pool = self.state.speech.client(self)
            else:
                pool = self._pool(work_ms > self.settings.heavy_work_ms)
            return await self._in_pool(
                lambda: self._encoded(self.session.handle(decoded, now)), pool
            )
        # Inline work is short and on the loop's thread: wall time meters it, and costs a
        # fraction of a CPU-clock read (see engines.work).
        outgoing = self.session.handle(decoded, now, time.perf_counter)
        values = _values(outgoing) if self.encoding == "json" else 0
        if values > JSON_INLINE_VALUES:
            pool = self._pool(values > JSON_HEAVY_VALUES)
            return await self._in_pool(lambda: self._encoded(outgoing), pool)
        return outgoing, [None] * len(outgoing)

    def _pool(self, heavy: bool) -> Executor:
        """The synthesis pool, or the heavy lane's turn of this connection."""
        return self.state.heavy.client(self) if heavy else self.state.executor

    def _encoded(self, outgoing: list[Outgoing]) -> Answers:
        """``outgoing`` with each frames block encoded (stamping leaves those unchanged);
        nothing more is encoded once the client is gone."""
        payloads: list[Payload | None] = []
        for item in outgoing:
            if self._peer_gone or self.aborted:
                return [], []
            payloads.append(self.encode(item.message) if isinstance(item.message, Frames) else None)
        return outgoing, payloads

    async def _in_pool(self, job: Callable[[], T], pool: Executor) -> T:
        """Run ``job`` in ``pool``, reading the client's messages ahead meanwhile."""
        future = self.loop.run_in_executor(pool, job)
        while not future.done() and not self._peer_gone and self.read_ahead.has_room():
            if self._receive_task is None:
                self._receive_task = asyncio.create_task(self._receive())
            receiving = self._receive_task
            waits: set[asyncio.Future[Any]] = {future, receiving}
            await asyncio.wait(waits, return_when=asyncio.FIRST_COMPLETED)
            if receiving.done():
                self._receive_task = None
                self._read(receiving.result())
        return await future

    def _read(self, received: Received) -> None:
        """Keep a message read while work runs; a ``cancel`` stops its request's work now,
        a closed socket all of it (and nothing read before it will be answered)."""
        if received.event["type"] == "websocket.disconnect":
            self._peer_gone = True
            self.session.stop_all_work()
            self.read_ahead.clear()
            self.read_ahead.push(received)
            return
        decoded = self._decode(received.event)
        if isinstance(decoded, Cancel) and not self.read_ahead.starts(decoded.id):
            self.session.stop_work(decoded.id)
        self.read_ahead.push(Received(received.event, received.at, decoded))
        if isinstance(decoded, Phonemes) and not self.read_ahead.starts(decoded.id):
            self.session.check_queued(decoded.id, self.read_ahead.phonemes(decoded.id))

    def _track_active(self) -> None:
        active = self.session.active_requests
        if active != self._active:
            self.metrics.requests_active.inc(active - self._active)
            if (active > 0) != (self._active > 0):
                self.state.overload.policy.set_streaming(self, active > 0)
            self._active = active
        stopped = self.session.stopped_work
        if stopped != self._stopped:
            self.metrics.work_stopped.inc(stopped - self._stopped)
            self._stopped = stopped

    # ---- sending --------------------------------------------------------------------------

    async def _send_all(
        self, items: Sequence[Outgoing], payloads: Sequence[Payload | None] = ()
    ) -> bool:
        """Stamp, encode (unless ``payloads`` holds the encoding) and send ``items`` in order;
        False once the connection is over (the client is gone, or missed a send deadline and
        was closed as a slow consumer)."""
        for index, item in enumerate(items):
            stamped_at = time.monotonic()
            message, clock = item.message, item.clock
            lag_s: float | None
            if type(message) is Frames and clock is not None:  # ``Outgoing.stamp``'s frames
                covered_at = stamped_at if item.covered_at is None else item.covered_at
                lag_s, first_s = clock.frames_sent(covered_at, stamped_at)
                engine: str | None = clock.engine
            else:
                self._observe(item)
                stamped = item.stamp(stamped_at)
                message, engine = stamped.message, stamped.engine
                lag_s, first_s = stamped.lag_s, stamped.first_frame_latency_s
            encoded = payloads[index] if index < len(payloads) else None
            payload = encoded or self.encode(message)
            try:
                await self._send_payload(payload)
            except TimeoutError:
                await self._slow_consumer()
                return False
            except _PEER_GONE:
                self.finished = True
                return False
            if engine is not None and isinstance(message, Frames):
                self._record(message, engine, lag_s, first_s, time.monotonic() - stamped_at)
        return True

    async def _send_payload(self, payload: bytes | str) -> None:
        """One send under the connection's send deadline: TimeoutError when it is missed."""
        task = self._task
        assert task is not None
        self.deadline.started(task)
        try:
            await _send(self.websocket, payload)
        except asyncio.CancelledError:
            if not self.deadline.expired or task.uncancel():
                raise
            raise TimeoutError from None
        finally:
            self.deadline.stopped()

    async def _close(self, code: int, reason: str, message: str | None = None) -> None:
        """Send a connection-level error ``reason`` with ``message`` (unless None), then
        close with ``code`` and ``reason``."""
        if message is None or await self._send_all([_connection_error(reason, message)]):
            self.finished = True
            await self._close_now(code, reason)

    def _observe(self, item: Outgoing) -> None:
        message = item.message
        engine = item.clock.engine if item.clock is not None else None
        metrics = self.metrics
        if isinstance(message, ErrorMessage):
            metrics.labelled(metrics.errors, message.code).inc()
            if message.fatal and engine is not None:
                metrics.labelled(metrics.requests, engine, "error").inc()
        elif isinstance(message, Done) and engine is not None:
            metrics.labelled(metrics.requests, engine, message.reason).inc()

    async def _slow_consumer(self) -> None:
        """The client does not read fast enough: close with 1008 and stop."""
        self.finished = True
        self.metrics.errors.labels(SLOW_CONSUMER).inc()
        await self._close_now(CloseCode.POLICY_VIOLATION, SLOW_CONSUMER)

    def _record(
        self,
        frames: Frames,
        engine: str,
        lag_s: float | None,
        first_frame_latency_s: float | None,
        sending_s: float,
    ) -> None:
        """Count a sent frames block of ``engine``, stamped with ``lag_s`` (and the request's
        ``first_frame_latency_s`` on its first block); its lag runs until its send returned
        (``sending_s`` after it was stamped): from socket to socket, as far as the process
        sees."""
        self.tally.frames_sent(
            engine, frames.n_frames, None if lag_s is None else lag_s + sending_s
        )
        if first_frame_latency_s is not None:
            self._first_frame_histogram(engine).observe(first_frame_latency_s)

    def _first_frame_histogram(self, engine: str) -> Any:
        """The first-frame histogram of ``engine`` (once per request: not tallied), kept
        per connection."""
        histogram = self._first_frame.get(engine)
        if histogram is None:
            metrics = self.metrics
            histogram = self._first_frame[engine] = metrics.labelled(metrics.first_frame, engine)
        return histogram

    async def _close_now(self, code: int, reason: str) -> None:
        try:
            async with asyncio.timeout(CLOSE_DEADLINE_S):
                await self.websocket.close(code=code, reason=reason)
        except (TimeoutError, *_PEER_GONE):
            return


def _values(outgoing: list[Outgoing]) -> int:
    """The numbers the frames blocks in ``outgoing`` carry."""
    return sum(len(item.message.data) // 4 for item in outgoing if isinstance(item.message, Frames))


def _connection_error(code: str, message: str) -> Outgoing:
    return Outgoing(ErrorMessage(code, message, None, True))


def _connection_ending(outgoing: list[Outgoing]) -> tuple[int, str] | None:
    """(close code, reason) if ``outgoing`` holds a connection-level error (fatal, no id)."""
    for item in outgoing:
        message = item.message
        if isinstance(message, ErrorMessage) and message.fatal and message.id is None:
            info = ERROR_CODES.get(message.code)
            code = (
                info.close_code
                if info is not None and info.close_code
                else CloseCode.INTERNAL_ERROR
            )
            return int(code), message.code
    return None
