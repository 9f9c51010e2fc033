"""A blocking client with the same surface as ``AsyncClient``, for code without asyncio.

Sketch: ``Client`` owns a private event loop running in a daemon thread and
an ``AsyncClient`` living on it. Every blocking method submits the matching
coroutine to that loop (``asyncio.run_coroutine_threadsafe``) and waits for
its result, so the frames, errors and close codes are exactly the async
client's. ``timeout`` (seconds, None for no limit) bounds each wait; a wait
that times out raises ``TimeoutError`` and leaves the request running.

Usage::

    with Client("ws://127.0.0.1:8000/v1/stream") as client:
        stream = client.start("viseme-lerp", "demo", fps=60)
        stream.send_phonemes([("HH", 0.0, 0.08), ("AY", 0.08, 0.3)])
        stream.end()
        for block in stream.frames():
            ...
        done = stream.done()
"""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Coroutine, Iterable, Iterator, Sequence
from concurrent.futures import TimeoutError as FutureTimeout
from types import TracebackType
from typing import Any, Literal, Self, TypeVar

from .client import (
    DEFAULT_CLOSE_TIMEOUT_S,
    DEFAULT_MAX_MESSAGE_BYTES,
    DEFAULT_OPEN_TIMEOUT_S,
    AsyncClient,
    MessageTap,
    Stream,
    StreamResult,
)
from .codec import DEFAULT_ENCODING
from .exceptions import ConnectionClosed, LipstreamClientError, LipstreamServerError
from .items import PhonemeLike
from .messages import (
    DEFAULT_FPS,
    ClientMessage,
    Done,
    Encoding,
    Frames,
    JsonMap,
    JsonValue,
    OutputProfile,
    Ready,
    Start,
)
from .resume import ResumePolicy

T = TypeVar("T")
_UNSET: Any = object()


class _LoopThread:
    """An event loop running forever in its own daemon thread."""

    def __init__(self, name: str) -> None:
        self.loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self.loop.run_forever, name=name, daemon=True)
        self._thread.start()

    def run(self, coroutine: Coroutine[Any, Any, T], timeout: float | None) -> T:
        future = asyncio.run_coroutine_threadsafe(coroutine, self.loop)
        try:
            return future.result(timeout)
        except FutureTimeout:
            future.cancel()
            raise TimeoutError(f"no result within {timeout} s") from None

    def stop(self) -> None:
        if self.loop.is_closed():
            return
        self.loop.call_soon_threadsafe(self.loop.stop)
        self._thread.join()
        self.loop.close()


class SyncStream:
    """A request of a ``Client``; the blocking counterpart of ``Stream``."""

    def __init__(self, client: Client, stream: Stream) -> None:
        self._client = client
        self._stream = stream

    @property
    def id(self) -> str:
        return self._stream.id

    @property
    def request(self) -> Start:
        return self._stream.request

    @property
    def is_over(self) -> bool:
        return self._stream.is_over

    @property
    def warnings(self) -> list[LipstreamServerError]:
        return list(self._stream.warnings)

    def send_phonemes(self, items: Iterable[PhonemeLike]) -> None:
        """See ``Stream.send_phonemes``."""
        batch = list(items)
        self._client._run(self._stream.send_phonemes(batch))

    def send_audio(self, pcm16: bytes | bytearray | memoryview, sample_rate: int) -> None:
        self._client._run(self._stream.send_audio(bytes(pcm16), sample_rate))

    def send_text(
        self,
        text: str,
        voice: str | None = None,
        rate: int | None = None,
        lang: str | None = None,
    ) -> None:
        """Have the server speak ``text`` as the next input (see ``Stream.send_text``)."""
        self._client._run(self._stream.send_text(text, voice, rate, lang))

    def send_words(
        self,
        timings: JsonValue,
        format: str = "auto",
        offset: float = 0.0,
        voice: str | None = None,
    ) -> None:
        """Send a TTS's timings as the next input (see ``Stream.send_words``)."""
        self._client._run(self._stream.send_words(timings, format, offset, voice))

    def end(self) -> None:
        self._client._run(self._stream.end())

    def cancel(self) -> None:
        self._client._run(self._stream.cancel())

    def interrupt(self, at: float, return_ms: float | None = None) -> None:
        self._client._run(self._stream.interrupt(at, return_ms))

    def ready(self, timeout: float | None = _UNSET) -> Ready:
        return self._client._run(self._stream.ready(), timeout)

    def done(self, timeout: float | None = _UNSET) -> Done:
        return self._client._run(self._stream.done(), timeout)

    def next_block(self, timeout: float | None = _UNSET) -> Frames | None:
        """The next frames block, waiting up to ``timeout``; None once the request is done."""
        return self._client._run(self._stream.next_block(), timeout)

    def frames(self, timeout: float | None = _UNSET) -> Iterator[Frames]:
        """Every block in arrival order until ``done``; ``timeout`` bounds each wait."""
        while (block := self.next_block(timeout)) is not None:
            yield block

    def poll(self) -> list[Frames]:
        """The blocks that arrived and were not read yet, without waiting."""
        return self._client._run(self._poll())

    async def _poll(self) -> list[Frames]:
        return self._stream.poll()

    def collect(self, timeout: float | None = _UNSET) -> StreamResult:
        """Wait (up to ``timeout`` in all) for ``ready``, every block and ``done``."""
        return self._client._run(self._stream.collect(), timeout)


class Client:
    """A blocking lipstream client; arguments as for ``AsyncClient``, plus ``timeout``,
    the default bound in seconds on every wait (None: no bound). ``on_message`` runs on
    the client's loop thread."""

    def __init__(
        self,
        url: str,
        encoding: Encoding = DEFAULT_ENCODING,
        token: str | None = None,
        origin: str | None = None,
        *,
        timeout: float | None = None,
        open_timeout: float = DEFAULT_OPEN_TIMEOUT_S,
        close_timeout: float = DEFAULT_CLOSE_TIMEOUT_S,
        max_message_bytes: int = DEFAULT_MAX_MESSAGE_BYTES,
        proxy: str | Literal[True] | None = True,
        on_message: MessageTap | None = None,
        resume: ResumePolicy | None = None,
    ) -> None:
        self.timeout = timeout
        self._async = AsyncClient(
            url,
            encoding,
            token,
            origin,
            open_timeout=open_timeout,
            close_timeout=close_timeout,
            max_message_bytes=max_message_bytes,
            proxy=proxy,
            on_message=on_message,
            resume=resume,
        )
        self._thread: _LoopThread | None = None

    def __enter__(self) -> Self:
        self.connect()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()

    @property
    def url(self) -> str:
        return self._async.url

    @property
    def encoding(self) -> Encoding:
        return self._async.encoding

    @property
    def warnings(self) -> list[LipstreamClientError]:
        return list(self._async.warnings)

    @property
    def closed(self) -> ConnectionClosed | None:
        return self._async.closed

    @property
    def active_ids(self) -> frozenset[str]:
        return self._async.active_ids

    def connect(self) -> None:
        """Start the loop thread and open the WebSocket."""
        if self._thread is not None:
            raise LipstreamClientError("the client is already connected")
        self._thread = _LoopThread(f"lipstream-client {self.url}")
        try:
            self._run(self._async.connect(), None)
        except BaseException:
            self._thread.stop()
            self._thread = None
            raise

    def close(self) -> None:
        """Close the connection with 1000 and stop the loop thread."""
        if self._thread is None:
            return
        try:
            self._run(self._async.close(), None)
        finally:
            self._thread.stop()
            self._thread = None

    def wait_closed(self, timeout: float | None = _UNSET) -> ConnectionClosed:
        return self._run(self._async.wait_closed(), timeout)

    def start(
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
    ) -> SyncStream:
        """Open a request (see ``AsyncClient.start``)."""
        stream = self._run(
            self._async.start(
                engine,
                character,
                id=id,
                fps=fps,
                channels=channels,
                output=output,
                emotion=emotion,
                latency_budget_ms=latency_budget_ms,
                options=options,
                phoneme_source=phoneme_source,
            )
        )
        return SyncStream(self, stream)

    def start_request(self, request: Start) -> SyncStream:
        return SyncStream(self, self._run(self._async.start_request(request)))

    def send(self, message: ClientMessage) -> None:
        self._run(self._async.send(message))

    def _run(self, coroutine: Coroutine[Any, Any, T], timeout: float | None = _UNSET) -> T:
        if self._thread is None:
            coroutine.close()
            raise LipstreamClientError("the client is not connected; use `with` or connect()")
        return self._thread.run(coroutine, self.timeout if timeout is _UNSET else timeout)
