"""The bridge: one request on a lipstream server, its frames forwarded to a sink on time.

Sketch: the bridge opens a request (``start`` with ``output.retarget`` set to the rig
``preset``, if one is named), sends its whole input at once (text for the server to
speak, phonemes, audio, or phonemes with their audio), and forwards each frame to the
sink at its due time on the bridge's own clock: frame ``i`` is due ``i / fps``
seconds after the first frame arrived. A frame that comes due while the one before
it is still waiting goes out at once; a frame whose successor is already due (the
bridge, or the server, fell a frame behind) is dropped, not queued, so the rig never
runs late, and ``BridgeReport.dropped`` counts it. The speech goes with the frames:
the server's speech for text (each chunk at its start time) or the input WAV is laid
on the frames' clock (``SpeechTrack``), written to ``wav`` when asked and played
through ``player`` from the moment the first frame goes out. The clock is injected
(``BridgeClock``): tests step it instead of waiting.

Usage::

    sink = LiveLinkSink(UdpSender("127.0.0.1", 11111), LiveLinkEncoder("lipstream"))
    bridge = Bridge(sink)
    report = asyncio.run(bridge.run("ws://127.0.0.1:8000/v1/stream",
                                    BridgeInput(text="Hello there."), preset="arkit52"))
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol
from urllib.parse import urlsplit

from .client import AsyncClient, Stream
from .exceptions import HandshakeRejected
from .items import PhonemeLike, phoneme_items
from .messages import DEFAULT_FPS, PCM16_BYTES, Encoding, OutputProfile, PhonemeItem
from .rest import RestClient
from .sinks.base import Delivery, Sink
from .sinks.errors import INVALID_AUDIO, SERVER_UNREACHABLE, BridgeError
from .sinks.sound import SoundPlayer, SpeechTrack, write_wav

AUDIO_CHUNK_S = 1.0
"""Seconds of input audio per ``audio`` message."""


class BridgeClock(Protocol):
    """The bridge's time: ``now()`` in seconds and ``sleep(seconds)``."""

    def now(self) -> float: ...

    async def sleep(self, seconds: float) -> None: ...


class MonotonicClock:
    """The machine's monotonic clock, and the event loop's sleep."""

    def now(self) -> float:
        return time.monotonic()

    async def sleep(self, seconds: float) -> None:
        await asyncio.sleep(seconds)


@dataclass(frozen=True, slots=True)
class BridgeInput:
    """What the request says: ``text`` (spoken by the server with ``voice`` and ``rate``),
    or ``phonemes`` and/or ``audio`` (mono PCM16 bytes at ``audio_rate`` Hz)."""

    text: str | None = None
    voice: str | None = None
    rate: int | None = None
    phonemes: tuple[PhonemeItem, ...] = ()
    audio: bytes | None = None
    audio_rate: int = 16000

    @classmethod
    def from_phonemes(
        cls, items: Sequence[PhonemeLike], audio: bytes | None = None, audio_rate: int = 16000
    ) -> BridgeInput:
        return cls(phonemes=phoneme_items(items), audio=audio, audio_rate=audio_rate)

    def __post_init__(self) -> None:
        if self.text is None and not self.phonemes and self.audio is None:
            raise ValueError("the bridge needs text, phonemes or audio")
        if self.text is not None and (self.phonemes or self.audio is not None):
            raise ValueError("text goes alone: the server speaks it and sends the speech")


@dataclass(frozen=True, slots=True)
class BridgeReport:
    """How a bridged request went: its ``channels`` at ``fps``, the ``frames`` the server
    made, those ``sent`` to the sink and those ``dropped`` late, what the sink's transport
    reported since it was made (``delivery``), the request's ``done`` reason, and the
    seconds of speech."""

    channels: tuple[str, ...]
    fps: float
    frames: int
    sent: int
    dropped: int
    delivery: Delivery
    reason: str
    speech_s: float = 0.0
    warnings: tuple[str, ...] = field(default_factory=tuple)


@dataclass
class _Progress:
    sent: int = 0
    dropped: int = 0
    next_index: int = 0
    first_at: float | None = None
    fed: int = 0
    played: int = 0


class Bridge:
    """Forwards a request's frames to ``sink`` (see the module sketch); ``on_frame`` is
    called with each frame's index once the sink has it. ``run`` again for another
    request: the sink is opened anew with its channels. The sink stays the caller's to
    ``close``."""

    def __init__(
        self,
        sink: Sink,
        clock: BridgeClock | None = None,
        wav: Path | None = None,
        player: SoundPlayer | None = None,
        on_frame: Callable[[int], None] | None = None,
    ) -> None:
        self.sink = sink
        self.clock: BridgeClock = clock or MonotonicClock()
        self.wav = wav
        self.player = player
        self.on_frame = on_frame
        self.track: SpeechTrack | None = None
        self._progress = _Progress()

    async def run(
        self,
        url: str,
        source: BridgeInput,
        *,
        engine: str | None = None,
        character: str | None = None,
        preset: str | None = None,
        fps: float = DEFAULT_FPS,
        token: str | None = None,
        encoding: Encoding = "msgpack",
    ) -> BridgeReport:
        if urlsplit(url).scheme not in ("ws", "wss") or not urlsplit(url).hostname:
            raise BridgeError(
                SERVER_UNREACHABLE, f"expected ws://HOST:PORT/v1/stream, got {url!r}", "--server"
            )
        if engine is None or character is None:
            default_engine, default_character = await _default_target(url, token)
            engine, character = engine or default_engine, character or default_character
        output = OutputProfile(retarget=preset) if preset is not None else None
        client = AsyncClient(url, encoding=encoding, token=token)
        try:
            await client.connect()
        except (OSError, TimeoutError, HandshakeRejected) as error:
            raise BridgeError(
                SERVER_UNREACHABLE, f"cannot stream from {url}: {error}", "--server"
            ) from None
        try:
            stream = await client.start(engine, character, fps=fps, output=output)
            await _send_input(stream, source)
            return await self._forward(stream, source)
        finally:
            await client.close()

    async def _forward(self, stream: Stream, source: BridgeInput) -> BridgeReport:
        self._progress, self.track = _Progress(), None
        ready = await stream.ready()
        self.sink.open(ready.channels, ready.fps)
        if source.audio is not None:
            self._place(source.audio, 0.0, source.audio_rate)
        period = 1.0 / ready.fps
        progress = self._progress
        while (block := await stream.next_block()) is not None:
            for offset, row in enumerate(block.rows()):
                index = block.first_frame + offset
                if index < progress.next_index:
                    continue
                progress.next_index = index + 1
                await self._take_speech(stream)
                if progress.first_at is None:
                    progress.first_at = self.clock.now()
                await self._feed_player()
                await self._deliver(index, row, progress.first_at + index * period, period)
        done = await stream.done()
        await self._take_speech(stream)
        if self.track is not None and self.wav is not None:
            write_wav(self.wav, self.track)
        if self.player is not None:
            await self._feed_player()
            await self.player.finish()
        return BridgeReport(
            channels=ready.channels,
            fps=ready.fps,
            frames=done.stats.frames,
            sent=progress.sent,
            dropped=progress.dropped,
            delivery=self.sink.delivery(),
            reason=done.reason,
            speech_s=self.track.duration if self.track is not None else 0.0,
            warnings=tuple(str(warning) for warning in stream.warnings),
        )

    async def _deliver(self, index: int, row: Sequence[float], due: float, period: float) -> None:
        late = self.clock.now() - due
        if late >= period:  # the next frame is due already: this one would only lag
            self._progress.dropped += 1
            return
        if late < 0:
            await self.clock.sleep(-late)
        self.sink.send(index, index * period, row)
        self._progress.sent += 1
        if self.on_frame is not None:
            self.on_frame(index)

    async def _take_speech(self, stream: Stream) -> None:
        """Lay the server's newly arrived speech chunks on the track and feed the player."""
        while self._progress.fed < len(stream.audio):
            chunk = stream.audio[self._progress.fed]
            self._progress.fed += 1
            self._place(chunk.pcm16, chunk.start or 0.0, chunk.sample_rate)
        await self._feed_player()

    def _place(self, pcm16: bytes, start_s: float, sample_rate: int) -> None:
        if self.track is None:
            self.track = SpeechTrack(sample_rate)
        if sample_rate != self.track.sample_rate:
            raise BridgeError(
                INVALID_AUDIO,
                f"speech at {sample_rate} Hz after speech at {self.track.sample_rate} Hz",
            )
        self.track.place(pcm16, start_s)

    async def _feed_player(self) -> None:
        """Feed the player the speech it has not had; start it, at the frames' point of the
        track, once the first frame went out and there is speech."""
        first_at = self._progress.first_at
        if self.player is None or self.track is None or first_at is None:
            return
        if not self.player.started:
            elapsed_samples = max(0, round((self.clock.now() - first_at) * self.track.sample_rate))
            self._progress.played = elapsed_samples * PCM16_BYTES
            await self.player.start(self.track.sample_rate)
        if self.track.n_bytes > self._progress.played:
            await self.player.feed(self.track.pcm16(self._progress.played))
            self._progress.played = self.track.n_bytes


async def _send_input(stream: Stream, source: BridgeInput) -> None:
    if source.text is not None:
        await stream.send_text(source.text, source.voice, source.rate)
    if source.phonemes:
        await stream.send_phonemes(source.phonemes)
    if source.audio is not None:
        step = max(2, int(AUDIO_CHUNK_S * source.audio_rate) * 2)
        for first in range(0, len(source.audio), step):
            await stream.send_audio(source.audio[first : first + step], source.audio_rate)
    await stream.end()


async def _default_target(url: str, token: str | None) -> tuple[str, str]:
    try:
        return await asyncio.to_thread(RestClient(url, token).default_target)
    except (OSError, ValueError) as error:
        raise BridgeError(
            SERVER_UNREACHABLE, f"cannot ask {url} what it serves: {error}", "--server"
        ) from None
