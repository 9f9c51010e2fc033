"""One streaming request: input in, profiled frame blocks out, and how it ends.

Sketch: an ``ActiveRequest`` owns one engine ``Synthesizer``. Each
``phonemes`` message is checked against what came before (order, phoneme
set, emotions, the server's limits), normalised to canonical phonemes and
fed, each item's own emotion riding on its span (it overrides the request's
for that phoneme); the frames the engine declares final go through the request's output
profile and leave as ``frames`` blocks of at most ``values_per_message``
values. ``Coverage`` remembers when the input first covered each time, so
every block carries the receipt time its lag is measured from.

Endings: ``end`` flushes the engine and sends ``done``; ``cancel`` sends
``done`` at once; ``interrupt`` at time ``at`` flushes the engine, sends the
frames before ``ceil(at × fps)`` not yet sent, then a block starting at that
frame that blends, in output space, from the face there to the rest pose
with a smoothstep (3u² − 2u³) over ``return_ms``, whose last frame is the
rest pose; then ``done``. A cut later than the input received so far is
taken at the input's end, so an interrupt never synthesizes silence.
"""

from __future__ import annotations

import math
from bisect import bisect_left
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from lipstream_client import AudioChunk, Done, DoneStats, Frames, PhonemeItem
from lipstream_client.errors import (
    ERROR_CODES,
    INVALID_AUDIO,
    INVALID_REQUEST,
    INVALID_TIMES,
    NON_MONOTONIC_TIMES,
    TOO_MANY_PHONEMES,
    UNKNOWN_EMOTION,
    UNKNOWN_PHONEME,
)
from lipstream_client.messages import DoneReason, JsonValue

from ..audio import Audio
from ..engines.base import Synthesizer, frame_count, frames_before
from ..errors import LipstreamError
from ..phonemes import normalize_phoneme
from ..timeline import EMOTIONS, PhonemeSpan
from .outgoing import Outgoing, RequestClock
from .profiles import ResolvedProfile

TIME_TOLERANCE_S = 1e-9
VALUES_PER_MESSAGE = 16_384
_MAX_KEY = 128
_MAX_ENTRIES = 256


class RequestError(LipstreamError):
    """Ends one request with a protocol error ``code``; ``details`` go into the error."""

    code = INVALID_REQUEST

    def __init__(
        self,
        message: str,
        *,
        code: str,
        where: str | None = None,
        details: Mapping[str, JsonValue] | None = None,
    ) -> None:
        super().__init__(message, where=where, code=code)
        self.details = dict(details or {})


def protocol_code(error: LipstreamError, fallback: str) -> str:
    """``error``'s code if the protocol defines it, else ``fallback``."""
    return error.code if error.code in ERROR_CODES else fallback


@dataclass(frozen=True)
class RequestLimits:
    """Per-request limits: phonemes, frames (utterance length × fps), the default
    return-to-rest time (ms) and the values in one ``frames`` message."""

    max_phonemes: int
    max_frames: int
    default_return_ms: float
    values_per_message: int = VALUES_PER_MESSAGE


class Coverage:
    """When the input came to cover each time: breakpoints (covered until s, received at s)."""

    def __init__(self) -> None:
        self.until: list[float] = []
        self.received: list[float] = []

    def advance(self, until: float, now: float) -> None:
        if not self.until or until > self.until[-1]:
            self.until.append(until)
            self.received.append(now)

    def received_at(self, time_s: float) -> float | None:
        """When the input first covered ``time_s``; None if it never did."""
        index = bisect_left(self.until, time_s - TIME_TOLERANCE_S)
        return self.received[index] if index < len(self.received) else None


@dataclass
class RequestSpec:
    """What ``start`` resolved for a request."""

    id: str
    engine: str
    fps: float
    phoneme_source: str
    uses_audio: bool
    profile: ResolvedProfile
    rest: np.ndarray
    clock: RequestClock


class ActiveRequest:
    """One request between ``ready`` and ``done``."""

    def __init__(self, spec: RequestSpec, synthesizer: Synthesizer, limits: RequestLimits) -> None:
        self.spec = spec
        self.synthesizer = synthesizer
        self.limits = limits
        self.coverage = Coverage()
        self.phonemes_end = 0.0
        self.n_phonemes = 0
        self.ends: list[float] = []
        self.audio_rate: int | None = None
        self.audio_s = 0.0
        self.next_frame = 0
        self.seq = 0
        self.sent: list[np.ndarray] = []
        width = spec.profile.n_channels
        self.rows_per_message = max(1, limits.values_per_message // width)

    @property
    def id(self) -> str:
        return self.spec.id

    # ---- input ----------------------------------------------------------------------------

    def add_phonemes(self, items: Sequence[PhonemeItem], now: float) -> list[Outgoing]:
        if self.n_phonemes + len(items) > self.limits.max_phonemes:
            raise RequestError(
                f"the request would hold {self.n_phonemes + len(items)} phonemes; the server "
                f"allows {self.limits.max_phonemes} per request",
                code=TOO_MANY_PHONEMES,
                where="items",
                details={"max_phonemes": self.limits.max_phonemes},
            )
        spans = [
            self._span(item, f"items[{index}]", self.phonemes_end if index == 0 else None)
            for index, item in enumerate(items)
        ]
        self._feed(spans, None, INVALID_REQUEST)
        self.n_phonemes += len(spans)
        self.ends.extend(span.end for span in spans)
        self.phonemes_end = spans[-1].end
        self.coverage.advance(self._covered_until(), now)
        return self._emit(self.synthesizer.frames(), now)

    def _span(self, item: PhonemeItem, where: str, previous_end: float | None) -> PhonemeSpan:
        if previous_end is not None and item.start < previous_end - TIME_TOLERANCE_S:
            raise RequestError(
                f"starts at {item.start} s, before the previous phoneme of this "
                f"request ends at {previous_end} s",
                code=NON_MONOTONIC_TIMES,
                where=f"{where}.start",
            )
        try:
            phoneme = normalize_phoneme(item.phoneme, self.spec.phoneme_source, f"{where}.phoneme")
        except LipstreamError as error:
            raise RequestError(
                error.message, code=protocol_code(error, UNKNOWN_PHONEME), where=error.where
            ) from None
        if item.emotion is not None and item.emotion not in EMOTIONS:
            raise RequestError(
                f"unknown emotion {item.emotion!r}; known: {', '.join(EMOTIONS)}",
                code=UNKNOWN_EMOTION,
                where=f"{where}.emotion",
            )
        if frame_count(item.end, self.spec.fps) > self.limits.max_frames:
            raise RequestError(
                f"ends at {item.end} s, beyond the server's limit of {self.limits.max_frames} "
                f"frames per request at {self.spec.fps:g} fps",
                code=INVALID_TIMES,
                where=f"{where}.end",
                details={"max_frames": self.limits.max_frames},
            )
        return PhonemeSpan(phoneme, item.start, item.end, item.emotion)

    def add_audio(self, chunk: AudioChunk, now: float) -> list[Outgoing]:
        if self.audio_rate is not None and chunk.sample_rate != self.audio_rate:
            raise RequestError(
                f"{chunk.sample_rate} Hz follows audio at {self.audio_rate} Hz in this request",
                code=INVALID_AUDIO,
                where="sample_rate",
            )
        limit_s = self.limits.max_frames / self.spec.fps
        if self.audio_s + chunk.duration > limit_s:
            raise RequestError(
                f"the request's audio would exceed the server's limit of {limit_s:g} s",
                code=INVALID_AUDIO,
                where="pcm16",
            )
        self.audio_rate = chunk.sample_rate
        self.audio_s += chunk.duration
        if not self.spec.uses_audio:
            return []
        self._feed([], Audio.from_pcm16(chunk.pcm16, chunk.sample_rate), INVALID_AUDIO)
        self.coverage.advance(self._covered_until(), now)
        return self._emit(self.synthesizer.frames(), now)

    def _covered_until(self) -> float:
        if self.spec.uses_audio and self.audio_rate is not None:
            return min(self.phonemes_end, self.audio_s)
        return self.phonemes_end

    def _feed(self, spans: list[PhonemeSpan], audio: Audio | None, fallback: str) -> None:
        try:
            self.synthesizer.feed(spans, audio)
        except LipstreamError as error:
            raise RequestError(
                error.message, code=protocol_code(error, fallback), where=error.where
            ) from None

    def _finish(self) -> np.ndarray:
        try:
            return self.synthesizer.finish()
        except LipstreamError as error:
            raise RequestError(
                error.message, code=protocol_code(error, INVALID_REQUEST), where=error.where
            ) from None

    # ---- endings --------------------------------------------------------------------------

    def end(self, now: float) -> list[Outgoing]:
        blocks = self._emit(self._finish(), now)
        return blocks + [self._done("end", self.next_frame)]

    def cancel(self) -> list[Outgoing]:
        return [self._done("cancel", self.next_frame)]

    def interrupt(self, at: float, return_ms: float | None, now: float) -> list[Outgoing]:
        fps = self.spec.fps
        cut = min(at, self.phonemes_end)
        first_return = frames_before(cut, fps)
        base = self.next_frame
        final = self._finish()
        unsent = self.spec.profile.apply(final) if len(final) else self._no_rows()
        blocks = self._send(unsent[: max(0, first_return - base)], now)
        face = self._face(first_return, base, unsent)
        seconds = (self.limits.default_return_ms if return_ms is None else return_ms) / 1000.0
        steps = max(0, math.ceil(seconds * fps - TIME_TOLERANCE_S))
        weights = _smoothstep(np.arange(steps + 1) / steps) if steps else np.ones(1)
        rows = face + (self.spec.rest - face) * weights[:, None]
        blocks += self._blocks(rows.astype(np.float32), first_return, covered_at=now)
        return blocks + [self._done("interrupt", first_return + steps + 1)]

    def _face(self, index: int, base: int, unsent: np.ndarray) -> np.ndarray:
        """The output frame at ``index`` of the uninterrupted timeline (clamped to its last
        frame; the rest pose if it has none)."""
        total = base + len(unsent)
        if total == 0:
            return self.spec.rest.astype(np.float64)
        index = min(index, total - 1)
        if index >= base:
            return np.asarray(unsent[index - base], dtype=np.float64)
        sent = np.concatenate(self.sent)
        return np.asarray(sent[index], dtype=np.float64)

    # ---- output ---------------------------------------------------------------------------

    def _no_rows(self) -> np.ndarray:
        return np.zeros((0, self.spec.profile.n_channels), dtype=np.float32)

    def _emit(self, frames: np.ndarray, now: float) -> list[Outgoing]:
        if not len(frames):
            return []
        return self._send(self.spec.profile.apply(frames), now)

    def _send(self, rows: np.ndarray, now: float) -> list[Outgoing]:
        """Send output rows continuing the timeline at ``next_frame``."""
        if not len(rows):
            return []
        first = self.next_frame
        self.sent.append(rows)
        self.next_frame += len(rows)
        return self._blocks(rows, first, None, now)

    def _blocks(
        self, rows: np.ndarray, first: int, covered_at: float | None, now: float | None = None
    ) -> list[Outgoing]:
        spec = self.spec
        blocks: list[Outgoing] = []
        for offset in range(0, len(rows), self.rows_per_message):
            chunk = rows[offset : offset + self.rows_per_message]
            index = first + offset
            received = (
                covered_at
                if covered_at is not None
                else self.coverage.received_at(index / spec.fps)
            )
            data = np.ascontiguousarray(chunk, dtype="<f4").tobytes()
            frames = Frames(spec.id, self.seq, index, spec.fps, spec.profile.n_channels, data)
            self.seq += 1
            blocks.append(Outgoing(frames, spec.clock, received if received is not None else now))
        return blocks

    def _done(self, reason: DoneReason, frames: int) -> Outgoing:
        stats = DoneStats(frames=frames, engine=json_safe(self.synthesizer.stats))
        return Outgoing(Done(self.spec.id, stats, reason), self.spec.clock)


def _smoothstep(u: np.ndarray) -> np.ndarray:
    return np.asarray(u * u * (3.0 - 2.0 * u))


def json_safe(stats: Mapping[str, Any]) -> dict[str, JsonValue]:
    """Engine statistics as a JSON map: numbers, strings and booleans; numpy scalars
    converted, non-finite numbers and other values left out."""
    safe: dict[str, JsonValue] = {}
    for key, value in stats.items():
        if isinstance(value, np.generic):
            value = value.item()
        if not 1 <= len(str(key)) <= _MAX_KEY or len(safe) == _MAX_ENTRIES:
            continue
        if _json_scalar(value):
            safe[str(key)] = value
    return safe


def _json_scalar(value: object) -> bool:
    if isinstance(value, (bool, str)):
        return True
    if isinstance(value, int):
        return -(2**63) <= value < 2**64
    return isinstance(value, float) and math.isfinite(value)
