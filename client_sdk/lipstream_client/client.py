"""The asyncio client: one WebSocket to ``/v1/stream``, many requests multiplexed on it.

Sketch: ``AsyncClient`` opens the connection with the subprotocol of the
chosen encoding (``lipstream.v1.msgpack`` or ``lipstream.v1.json``), then a
background reader task decodes every incoming message with the sans-I/O
codec and dispatches it by request id. Each request is a ``Stream``: its
``ready`` and ``done`` resolve futures, its ``frames`` go to an unbounded
per-request queue (so one slow consumer never stalls the other requests on
the connection), and a fatal ``error`` ends it with a
``LipstreamServerError``. When the connection closes, every open request
ends with the ``ConnectionClosed`` subclass that names the close code
(``ServerBusy`` for 1013), unless the client was given a ``ResumePolicy``:
then each request keeps a ``RequestLog`` of its input and progress, and a
connection that breaks or that the server closes as going away, failed or
busy (``RESUMABLE_CLOSE_CODES``) is opened again with backoff; each open
request that was neither cancelled nor interrupted is started again with
``resume`` (the frames and speech chunks it holds) and its whole input, so
that it receives the frames and speech it lacks and no other
(docs/reference/protocol.md, *Resuming*). Input sent
while the connection is down waits in the log. Sending validates each
message with the codec first, so a bad argument raises locally
(``EncodeError``) and never reaches the wire.

Usage::

    async with AsyncClient("ws://127.0.0.1:8000/v1/stream") as client:
        stream = await client.start("viseme-lerp", "demo", fps=60)
        await stream.send_phonemes([("HH", 0.0, 0.08), ("AY", 0.08, 0.3)])
        await stream.end()
        async for block in stream.frames():
            ...  # block.rows(): (n_frames, n_channels) floats from block.first_frame
        done = await stream.done()
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import time
from collections.abc import AsyncIterator, Callable, Iterable, Sequence
from dataclasses import dataclass
from types import TracebackType
from typing import Literal, Self, TypeAlias

from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed as WebSocketClosed
from websockets.exceptions import InvalidHandshake, InvalidStatus
from websockets.typing import Origin, Subprotocol

from .codec import DEFAULT_ENCODING, decode, encode, encoding_for_subprotocol, subprotocol_for
from .errors import RETRYABLE_CLOSE_CODES, CloseCode, ProtocolError
from .exceptions import (
    ConnectionClosed,
    HandshakeRejected,
    LipstreamClientError,
    LipstreamServerError,
    ProtocolViolation,
    ResumeFailed,
    closed_error,
    retry_delay_s,
)
from .frame_timeline import FrameTimeline
from .items import PhonemeLike, is_loopback_url, phoneme_items
from .messages import (
    DEFAULT_FPS,
    AudioChunk,
    Cancel,
    ClientMessage,
    Done,
    Encoding,
    End,
    ErrorMessage,
    Frames,
    Interrupt,
    JsonMap,
    JsonValue,
    OutputProfile,
    Phonemes,
    Ready,
    ServerMessage,
    Start,
    Text,
    Words,
)
from .resume import RequestLog, ResumePolicy

DEFAULT_MAX_MESSAGE_BYTES = 16 << 20
DEFAULT_OPEN_TIMEOUT_S = 10.0
DEFAULT_CLOSE_TIMEOUT_S = 5.0
ABNORMAL_CLOSURE = 1006
RESUMABLE_CLOSE_CODES: frozenset[int | None] = frozenset(
    {None, ABNORMAL_CLOSURE, CloseCode.INTERNAL_ERROR, *RETRYABLE_CLOSE_CODES}
)
"""Closes after which open requests are resumed: the connection broke (no close frame,
1006), or the server went away, failed or asked for a retry."""
_HANDSHAKE_BODY_CHARS = 1000  # room for a JSON error body whole

MessageTap: TypeAlias = Callable[[ServerMessage, float], None]


class RequestOver(LipstreamClientError):
    """The request already ended (``done`` or a fatal error): its id may be reused."""


@dataclass(frozen=True, slots=True)
class StreamResult:
    """Everything one request produced: its ``ready``, its ``frames`` blocks in arrival
    order, its ``done``, and the speech the server sent for its ``text`` messages."""

    ready: Ready
    frames: tuple[Frames, ...]
    done: Done
    audio: tuple[AudioChunk, ...] = ()

    def speech_pcm16(self) -> bytes:
        """The server's speech as one PCM16 stream from the first chunk's ``start``
        (chunks in order of their ``start``; empty without ``text`` input)."""
        return b"".join(chunk.pcm16 for chunk in sorted(self.audio, key=_chunk_start))

    @property
    def channels(self) -> tuple[str, ...]:
        return self.ready.channels

    def timeline(self) -> FrameTimeline:
        """The final timeline: the blocks assembled by frame index (later blocks supersede
        earlier rows), ``done.stats.frames`` long."""
        timeline = FrameTimeline(self.ready.fps, self.frames)
        timeline.truncate(self.done.stats.frames)
        return timeline

    def rows(self) -> list[list[float]]:
        """The final frames from index 0, shape (n_frames, n_channels)."""
        return self.timeline().rows()


def _chunk_start(chunk: AudioChunk) -> float:
    return chunk.start or 0.0


@dataclass(frozen=True, slots=True)
class _Finished:
    """Queue terminator: the request ended with ``done`` or with ``error``."""

    done: Done | None
    error: LipstreamClientError | None


class Stream:
    """One request on an ``AsyncClient`` connection, named by ``id``.

    Input: ``send_phonemes``, ``send_audio`` or ``send_text``, then ``end``; or
    ``cancel`` or ``interrupt`` at any time. Output: ``ready()``, the ``frames()``
    blocks (or ``poll()`` without waiting), ``audio`` (the speech the server sent
    for ``send_text``, each chunk with its ``start``), and ``done()``. A fatal error for this
    request or the loss of the connection raises from all three.
    """

    def __init__(self, client: AsyncClient, request: Start, log: RequestLog | None) -> None:
        loop = asyncio.get_running_loop()
        self._client = client
        self.request = request
        self._log = log
        self._ready: asyncio.Future[Ready] = loop.create_future()
        self._done: asyncio.Future[Done] = loop.create_future()
        self._queue: asyncio.Queue[Frames | _Finished] = asyncio.Queue()
        self._finished: _Finished | None = None
        self.warnings: list[LipstreamServerError] = []
        """Non-fatal errors about this request (e.g. ``request_finished``)."""
        self.audio: list[AudioChunk] = []
        """The speech chunks the server sent for this request's ``text``, in arrival order."""

    @property
    def id(self) -> str:
        return self.request.id

    @property
    def resumes(self) -> int:
        """How many times the request was resumed on a new connection."""
        return self._log.resumes if self._log is not None else 0

    @property
    def is_over(self) -> bool:
        """True once ``done`` or a fatal error arrived (frames may still wait in the queue)."""
        return self._done.done()

    # Input.

    async def send_phonemes(self, items: Iterable[PhonemeLike]) -> None:
        """Send the next phonemes: ``PhonemeItem``s, ``(phoneme, start, end[, emotion])``
        tuples or mappings with those keys; times in seconds on the utterance clock.
        An empty batch sends nothing."""
        batch = phoneme_items(items)
        if batch:
            await self._send(Phonemes(self.id, batch))

    async def send_audio(self, pcm16: bytes | bytearray | memoryview, sample_rate: int) -> None:
        """Send the next chunk of mono signed 16-bit little-endian audio at ``sample_rate`` Hz."""
        await self._send(AudioChunk(self.id, sample_rate, bytes(pcm16)))

    async def send_text(
        self,
        text: str,
        voice: str | None = None,
        rate: int | None = None,
        lang: str | None = None,
    ) -> None:
        """Have the server speak ``text`` (espeak-ng language ``lang``, e.g. ``de``, and
        ``voice``: with ``lang`` a variant such as ``f3``, else a whole voice name; ``rate``
        in words per minute; None: its defaults) as the next input: it sends the speech
        back as ``audio`` chunks with their start times (``audio``) and the frames as usual."""
        await self._send(Text(self.id, text, voice, rate, lang))

    async def send_words(
        self,
        timings: JsonValue,
        format: str = "auto",
        offset: float = 0.0,
        voice: str | None = None,
    ) -> None:
        """Send a TTS's timings (one chunk of them) as the next input: ``timings`` is the
        provider's JSON value (ElevenLabs ``alignment``, Azure events, Polly marks, Cartesia
        or Hume phoneme timestamps, a word list) or JSON lines text, in ``format`` (one of
        ``TIMING_FORMATS``; ``auto``: detected), its times plus ``offset`` seconds on the
        utterance clock; ``voice``: the espeak-ng voice for words CMUdict lacks (a voice of
        another language, ``de``, pronounces every word in it)."""
        await self._send(Words(self.id, timings, format, offset, voice))

    async def end(self) -> None:
        """No more input: the server sends the remaining frames, then ``done``."""
        await self._send(End(self.id))

    async def cancel(self) -> None:
        """Abandon the request: no more frames; ``done`` with reason ``cancel`` follows."""
        await self._send(Cancel(self.id))

    async def interrupt(self, at: float, return_ms: float | None = None) -> None:
        """Cut the utterance off at ``at`` seconds; the face returns to rest over
        ``return_ms`` (None: the server's default), then ``done`` with reason ``interrupt``."""
        await self._send(Interrupt(self.id, at, return_ms))

    async def _send(self, message: ClientMessage) -> None:
        if self._done.done():
            error = self._done.exception()
            if error is not None:
                raise error
            raise RequestOver(f"request {self.id!r} is over; start a new one")
        if self._log is None:
            await self._client.send(message)
            return
        encode(message, self._client.encoding)  # EncodeError before recording
        assert not isinstance(message, Start)
        self._log.record(message)
        await self._client._send_logged(self)

    # Output.

    async def ready(self) -> Ready:
        """The server's resolved parameters (channels, fps, fidelity, lookahead)."""
        return await asyncio.shield(self._ready)

    async def done(self) -> Done:
        """The request's ``done`` (stats and reason). Frames not yet read stay queued."""
        return await asyncio.shield(self._done)

    async def next_block(self) -> Frames | None:
        """The next frames block, waiting for it; None once the request is done."""
        if self._finished is None:
            item = await self._queue.get()
            if isinstance(item, Frames):
                return item
            self._finished = item
        self._raise_error()
        return None

    async def frames(self) -> AsyncIterator[Frames]:
        """Every frames block in arrival order, until ``done``."""
        while (block := await self.next_block()) is not None:
            yield block

    def poll(self) -> list[Frames]:
        """The blocks that have arrived and were not read yet, without waiting.

        Returns [] once the request is done; raises the request's error after
        the blocks that preceded it were returned.
        """
        blocks: list[Frames] = []
        while self._finished is None and not self._queue.empty():
            item = self._queue.get_nowait()
            if isinstance(item, Frames):
                blocks.append(item)
            else:
                self._finished = item
        if self._finished is not None and not blocks:
            self._raise_error()
        return blocks

    async def collect(self) -> StreamResult:
        """Wait for the whole request: ``ready``, every block, and ``done``."""
        ready = await self.ready()
        blocks = [block async for block in self.frames()]
        return StreamResult(ready, tuple(blocks), await self.done(), tuple(self.audio))

    def _raise_error(self) -> None:
        if self._finished is not None and self._finished.error is not None:
            raise self._finished.error

    # Dispatch, called by the client's reader task.

    def _on_message(self, message: ServerMessage) -> bool:
        """Handle one message for this request; True when the request has ended."""
        if isinstance(message, Frames):
            if self._log is not None:
                self._log.on_frames(message)
            self._queue.put_nowait(message)
            return False
        if isinstance(message, AudioChunk):
            if self._log is not None:
                self._log.on_audio()
            self.audio.append(message)
            return False
        if isinstance(message, Ready):
            if self._log is not None:
                self._log.on_ready(message)
            if not self._ready.done():
                self._ready.set_result(message)
            return False
        if isinstance(message, Done):
            self._finish(_Finished(message, None))
            return True
        assert isinstance(message, ErrorMessage)
        error = LipstreamServerError.from_message(message)
        if not message.fatal:
            self.warnings.append(error)
            return False
        self._fail(error)
        return True

    def _fail(self, error: LipstreamClientError) -> None:
        self._finish(_Finished(None, error))

    def _finish(self, finished: _Finished) -> None:
        if self._done.done():
            return
        for future in (self._ready, self._done):
            if future.done():
                continue
            if finished.error is not None:
                future.set_exception(finished.error)
                future.exception()  # retrieved here: the caller may never await it
            elif future is self._done and finished.done is not None:
                self._done.set_result(finished.done)
            else:
                future.set_exception(
                    LipstreamClientError(f"request {self.id!r} ended without a ready message")
                )
                future.exception()
        self._queue.put_nowait(finished)


class AsyncClient:
    """An asyncio connection to a lipstream server's ``/v1/stream``.

    ``encoding`` is ``msgpack`` (binary frames, the default) or ``json``
    (text frames); ``token`` is sent as ``Authorization: Bearer``; ``origin``
    sets the ``Origin`` header for servers with an allow-list.
    ``max_message_bytes`` bounds an incoming message. ``on_message``, if
    given, sees every valid server message with its arrival time
    (``time.perf_counter()`` seconds, taken before decoding) just before it
    is dispatched; it runs on the event loop and must not block. With a
    ``resume`` policy, requests survive a lost connection (module docstring).
    Use the client as an async context manager, or call ``connect()`` and
    ``close()``.
    """

    def __init__(
        self,
        url: str,
        encoding: Encoding = DEFAULT_ENCODING,
        token: str | None = None,
        origin: str | None = None,
        *,
        open_timeout: float = DEFAULT_OPEN_TIMEOUT_S,
        close_timeout: float = DEFAULT_CLOSE_TIMEOUT_S,
        max_message_bytes: int = DEFAULT_MAX_MESSAGE_BYTES,
        proxy: str | Literal[True] | None = True,
        on_message: MessageTap | None = None,
        resume: ResumePolicy | None = None,
    ) -> None:
        subprotocol_for(encoding)  # ValueError for an unknown encoding
        self.url = url
        self.requested_encoding = encoding
        self.encoding: Encoding = encoding
        self._token = token
        self._origin = origin
        self._open_timeout = open_timeout
        self._close_timeout = close_timeout
        self._max_message_bytes = max_message_bytes
        self._on_message = on_message
        # A proxy can never reach this machine's own loopback interface.
        self._proxy = None if is_loopback_url(url) else proxy
        self._connection: ClientConnection | None = None
        self._reader: asyncio.Task[None] | None = None
        self._streams: dict[str, Stream] = {}
        self._ids = itertools.count(1)
        self._connection_error: LipstreamServerError | None = None
        self._closed: ConnectionClosed | None = None
        self._resume = resume
        self._send_lock = asyncio.Lock()
        self._resuming: asyncio.Task[None] | None = None
        self._resume_attempt = 0
        self._closing = False
        self.warnings: list[LipstreamClientError] = []
        """Non-fatal errors that concern no open request (e.g. ``unknown_request``)."""

    async def __aenter__(self) -> Self:
        await self.connect()
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        await self.close()

    async def connect(self) -> None:
        """Open the WebSocket; HandshakeRejected if the server refuses the upgrade."""
        if self._connection is not None:
            raise LipstreamClientError("the client is already connected")
        await self._open()

    async def _open(self) -> None:
        headers = {"Authorization": f"Bearer {self._token}"} if self._token else None
        try:
            self._connection = await connect(
                self.url,
                subprotocols=[Subprotocol(subprotocol_for(self.requested_encoding))],
                additional_headers=headers,
                origin=Origin(self._origin) if self._origin else None,
                compression=None,
                max_size=self._max_message_bytes,
                open_timeout=self._open_timeout,
                close_timeout=self._close_timeout,
                proxy=self._proxy,
            )
        except InvalidStatus as error:
            response = error.response
            body = response.body.decode("utf-8", "replace")[:_HANDSHAKE_BODY_CHARS]
            raise HandshakeRejected(
                response.status_code, body.strip(), response.headers.get("Retry-After")
            ) from None
        except InvalidHandshake as error:
            raise LipstreamClientError(
                f"WebSocket handshake with {self.url} failed: {error}"
            ) from None
        negotiated = encoding_for_subprotocol(self._connection.subprotocol)
        self.encoding = negotiated or DEFAULT_ENCODING
        self._reader = asyncio.create_task(
            self._read(self._connection), name=f"lipstream-reader {self.url}"
        )

    async def close(self) -> None:
        """Close with 1000 and wait for the reader; open requests end with ConnectionClosed
        (also those waiting to be resumed)."""
        self._closing = True
        if self._resuming is not None:
            self._resuming.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._resuming
            self._resuming = None
            self._give_up(closed_error(CloseCode.NORMAL, "closed by the client"))
        if self._connection is None:
            return
        await self._connection.close(CloseCode.NORMAL)
        if self._reader is not None:
            await self._reader

    @property
    def closed(self) -> ConnectionClosed | None:
        """Why the connection closed, once it has."""
        return self._closed

    @property
    def active_ids(self) -> frozenset[str]:
        return frozenset(self._streams)

    async def wait_closed(self) -> ConnectionClosed:
        """Wait until the connection closes (by either side) for good, after any resumes,
        and say why."""
        if self._reader is None:
            raise LipstreamClientError("the client is not connected")
        while self._closed is None:
            if self._resuming is not None:
                await asyncio.shield(self._resuming)
            else:
                await asyncio.shield(self._reader)
        return self._closed

    async def start(
        self,
        engine: str,
        character: str,
        *,
        id: str | None = None,
        fps: float = DEFAULT_FPS,
        channels: Sequence[str] | None = None,
        output: OutputProfile | None = None,
        emotion: str | None = None,
        latency_budget_ms: float | None = None,
        options: JsonMap | None = None,
        phoneme_source: str | None = None,
    ) -> Stream:
        """Open a request and return its ``Stream`` without waiting for ``ready``.

        ``id`` defaults to a fresh ``r1``, ``r2``, ...; it must not name a
        request still open on this connection (ValueError).
        """
        request = Start(
            id=id if id is not None else self._fresh_id(),
            engine=engine,
            character=character,
            fps=fps,
            channels=tuple(channels) if channels is not None else None,
            output=output,
            emotion=emotion,
            latency_budget_ms=latency_budget_ms,
            options=dict(options or {}),
            phoneme_source=phoneme_source,
        )
        return await self.start_request(request)

    async def start_request(self, request: Start) -> Stream:
        """Open the request described by a ``Start`` message."""
        if request.id in self._streams:
            raise ValueError(f"request id {request.id!r} is still open on this connection")
        self._check_open()
        encoded = encode(request, self.encoding)  # EncodeError before registering
        log = RequestLog(request) if self._resume is not None else None
        stream = Stream(self, request, log)
        self._streams[request.id] = stream
        try:
            async with self._send_lock:
                if self._connection is not None:  # else the resume starts it
                    await self._send_encoded(encoded)
        except ConnectionClosed:
            if self._resuming is None or request.id not in self._streams:
                self._streams.pop(request.id, None)
                raise
        except BaseException:
            self._streams.pop(request.id, None)
            raise
        return stream

    async def _send_logged(self, stream: Stream) -> None:
        """Send the input ``stream`` recorded and has not sent; while the connection is
        down, leave it for the resume."""
        assert stream._log is not None
        async with self._send_lock:
            if self._connection is None:
                return
            try:
                for message in stream._log.unsent():
                    await self._send_encoded(encode(message, self.encoding))
            except ConnectionClosed:
                if self._resuming is None or stream.id not in self._streams:
                    raise

    async def send(self, message: ClientMessage) -> None:
        """Validate and send any client message (``Stream`` does this for its request)."""
        self._check_open()
        await self._send_encoded(encode(message, self.encoding))

    def _fresh_id(self) -> str:
        while (candidate := f"r{next(self._ids)}") in self._streams:
            pass
        return candidate

    def _check_open(self) -> None:
        if self._closed is not None:
            raise self._closed
        if self._connection is None and self._resuming is None:
            raise LipstreamClientError("the client is not connected; use `async with` or connect()")

    async def _send_encoded(self, payload: bytes | str) -> None:
        connection = self._connection
        if connection is None:  # lost while a resume was sending
            raise self._closed or closed_error(None, "the connection was lost")
        try:
            await connection.send(payload)
        except WebSocketClosed:
            if self._reader is not None:
                await asyncio.shield(self._reader)
            raise self._closed or closed_error(None, "") from None

    async def _read(self, connection: ClientConnection) -> None:
        try:
            async for data in connection:
                received_at = time.perf_counter()
                self._resume_attempt = 0
                message = decode(
                    data, self.encoding, max_size=self._max_message_bytes, sender="server"
                )
                if self._on_message is not None and not isinstance(message, ProtocolError):
                    self._on_message(message, received_at)  # type: ignore[arg-type]
                self._dispatch(message)
        except WebSocketClosed:
            pass
        finally:
            self._on_closed(connection)

    def _dispatch(self, message: ServerMessage | ClientMessage | ProtocolError) -> None:
        if isinstance(message, ProtocolError):
            self._on_violation(message)
            return
        if isinstance(message, ErrorMessage) and message.id is None:
            error = LipstreamServerError.from_message(message)
            if message.fatal:
                self._connection_error = error
            else:
                self.warnings.append(error)
            return
        stream = self._streams.get(message.id) if message.id is not None else None
        if stream is None:
            if isinstance(message, ErrorMessage):
                self.warnings.append(LipstreamServerError.from_message(message))
            else:
                self.warnings.append(
                    LipstreamClientError(
                        f"{message.type} for request {message.id!r}, which is not open"
                    )
                )
            return
        assert not isinstance(message, (Start, Phonemes, Text, Words, End, Cancel, Interrupt))
        if stream._on_message(message):
            del self._streams[stream.id]

    def _on_violation(self, error: ProtocolError) -> None:
        violation = ProtocolViolation(error)
        stream = self._streams.get(error.id) if error.id is not None else None
        if stream is not None and error.fatal:
            del self._streams[stream.id]
            stream._fail(violation)
        else:
            self.warnings.append(violation)

    def _on_closed(self, connection: ClientConnection) -> None:
        code = connection.close_code
        reason = connection.close_reason or ""
        closed = closed_error(code, reason, self._connection_error)
        self._connection_error = None
        kept = self._resumable(closed)
        for stream in list(self._streams.values()):
            if stream not in kept:
                del self._streams[stream.id]
                stream._fail(closed)
        if not kept:
            self._closed = closed
            return
        self._connection = None
        for stream in kept:
            assert stream._log is not None
            stream._log.rewind()
        if self._resuming is None:
            self._resuming = asyncio.create_task(
                self._resume_requests(closed), name=f"lipstream-resume {self.url}"
            )

    def _resumable(self, closed: ConnectionClosed) -> list[Stream]:
        """The open requests to resume after ``closed``: none without a policy, after
        ``close()`` or after a close that a retry would not fix."""
        if self._resume is None or self._closing or closed.code not in RESUMABLE_CLOSE_CODES:
            return []
        return [s for s in self._streams.values() if s._log is not None and s._log.resumable]

    async def _resume_requests(self, lost: ConnectionClosed) -> None:
        """Reconnect with backoff and replay every kept request (``RequestLog.replay``);
        after ``attempts`` failures in a row, fail them with ``ResumeFailed``."""
        assert self._resume is not None
        policy = self._resume
        last: LipstreamClientError = lost
        while self._streams and self._resume_attempt < policy.attempts:
            attempt = self._resume_attempt
            self._resume_attempt += 1
            await asyncio.sleep(
                retry_delay_s(last, attempt, policy.backoff_s, policy.max_backoff_s)
            )
            try:
                async with self._send_lock:
                    await self._open()
                    for stream in list(self._streams.values()):
                        assert stream._log is not None
                        for message in stream._log.replay():
                            await self._send_encoded(encode(message, self.encoding))
            except (LipstreamClientError, OSError, TimeoutError) as error:
                last = (
                    error
                    if isinstance(error, LipstreamClientError)
                    else LipstreamClientError(f"could not connect to {self.url}: {error!r}")
                )
                self._connection = None
                continue
            self._resuming = None
            return
        self._resuming = None
        if self._streams:
            self._give_up(ResumeFailed(lost, last, self._resume_attempt))

    def _give_up(self, error: ConnectionClosed) -> None:
        self._closed = error
        for stream in self._streams.values():
            stream._fail(error)
        self._streams.clear()
