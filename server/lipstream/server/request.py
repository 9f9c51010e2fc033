"""One streaming request: input in, profiled frame blocks out, and how it ends.

Sketch: an ``ActiveRequest`` owns one engine ``Synthesizer``. Each
``phonemes`` message is checked against what came before (order, phoneme
set, emotions, the server's limits), normalised to canonical phonemes and
fed, each item's own emotion riding on its span (it overrides the request's
for that phoneme); the frames the engine declares final go through the request's output
profile and leave as ``frames`` blocks of at most ``values_per_message``
values. ``Coverage`` remembers when the input first covered each time, so
every block carries the receipt time its lag is measured from.

Memory: rows leave as they are sent; a request keeps only a ring of the
last ``tail_values`` values sent (``SentTail``, at least one frame), which
is all ``interrupt`` may start its return from. Its output, the frames up to
the end of its input times its channels, is checked against ``max_values``
(and the connection's share, which the ``Session`` passes in) before the
engine sees the phonemes that would make it larger.

Audio alone: a request may send only ``audio`` chunks, then ``end``, when its
model can be driven by audio alone (``Model.accepts_audio_only``: ``hmm`` with a
vocal model); its input then covers the audio received. Any other request
that sent audio and no phonemes ends at ``end`` with ``audio_only_unsupported``.

Endings: ``end`` flushes the engine, then settles the face: the frames after the
last one blend from it to the rest pose with the same smoothstep over the default
``return_ms`` (at least one frame; the last one is the rest pose, so a face never
stays mid-word, whatever the engine), then ``done``; ``cancel`` sends
``done`` at once; ``interrupt`` at time ``at`` flushes the engine, sends the
frames before ``ceil(at × fps)`` not yet sent, then a block starting at that
frame that blends, in output space, from the face there to the rest pose
with a smoothstep (3u² − 2u³) over ``return_ms``, whose last frame is the
rest pose; then ``done``. A cut later than the input received so far is
taken at the input's end, so an interrupt never synthesizes silence; a cut
before the oldest frame the tail still holds is taken at that frame.
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
    AUDIO_ONLY_UNSUPPORTED,
    ERROR_CODES,
    INVALID_AUDIO,
    INVALID_REQUEST,
    INVALID_TIMES,
    NON_MONOTONIC_TIMES,
    OUTPUT_TOO_LARGE,
    TOO_MANY_PHONEMES,
    UNKNOWN_EMOTION,
    UNKNOWN_PHONEME,
)
from lipstream_client.messages import MAX_FPS, MAX_RETURN_MS, MAX_SEQ, DoneReason, JsonValue

from ..audio import Audio
from ..engines.base import Synthesizer, frame_count, frames_before
from ..errors import LipstreamError
from ..output.profiles import ResolvedProfile
from ..phonemes import normalize_phoneme
from ..timeline import EMOTIONS, NormalizedSpans, PhonemeSpan
from .outgoing import Outgoing, RequestClock

TIME_TOLERANCE_S = 1e-9
VALUES_PER_MESSAGE = 16_384
SENT_TAIL_VALUES = 65_536
_MAX_KEY = 128
_LITTLE_FLOAT32 = np.dtype("<f4")
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
    return-to-rest time (ms), the values in one ``frames`` message, the output values
    (frames × channels), the values sent that ``interrupt`` can still return from, and
    the utterance length (s: engines may hold state for every moment of it, at their own
    rate whatever the fps). None: no limit."""

    max_phonemes: int
    max_frames: int
    default_return_ms: float
    values_per_message: int = VALUES_PER_MESSAGE
    max_values: int | None = None
    tail_values: int = SENT_TAIL_VALUES
    max_seconds: float | None = None


def most_blocks(limits: RequestLimits) -> int:
    """The most ``frames`` blocks one request may send: a block per frame up to its limit
    (one more for audio that ends on the limit), then an interrupt's return to rest of
    ``MAX_RETURN_MS`` at ``MAX_FPS``, a block per row."""
    return limits.max_frames + 1 + math.ceil(MAX_RETURN_MS * MAX_FPS / 1000.0) + 1


class SentTail:
    """The last frames sent, at most ``capacity`` rows in a ring (row i of the request's
    timeline at ``i % capacity``), grown on demand up to the capacity."""

    def __init__(self, capacity: int, width: int) -> None:
        self.capacity = capacity
        self.rows = np.zeros((0, width), dtype=np.float32)
        self.stop = 0

    @property
    def oldest(self) -> int:
        """The index of the oldest frame held (0 when none was sent)."""
        return max(0, self.stop - self.capacity)

    def extend(self, rows: np.ndarray) -> None:
        """Append ``rows``, the frames from ``stop`` on."""
        at = self.stop % self.capacity
        if at + len(rows) <= len(self.rows):  # held already, no wrap: every call but a few
            self.rows[at : at + len(rows)] = rows
            self.stop += len(rows)
            return
        stop = self.stop + len(rows)
        size = min(self.capacity, stop)
        if len(self.rows) < size:
            capacity = min(self.capacity, max(size, 2 * len(self.rows)))
            grown = np.zeros((capacity, self.rows.shape[1]), dtype=np.float32)
            grown[: len(self.rows)] = self.rows
            self.rows = grown
        kept = rows[-self.capacity :]
        at = (stop - len(kept)) % self.capacity
        first = min(len(kept), self.capacity - at)
        self.rows[at : at + first] = kept[:first]
        self.rows[: len(kept) - first] = kept[first:]
        self.stop = stop

    def row(self, index: int) -> np.ndarray:
        """Frame ``index``, which must lie in [oldest, stop)."""
        if not self.oldest <= index < self.stop:
            raise IndexError(f"frame {index} is not in the tail [{self.oldest}, {self.stop})")
        return np.asarray(self.rows[index % self.capacity])


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
    audio_only: bool = False
    """The model can be driven by audio alone (``Model.accepts_audio_only``)."""
    character: str = ""
    """The character the model serves (its duration model reads word timings)."""


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
        width = spec.profile.n_channels
        self.tail = SentTail(max(1, limits.tail_values // width), width)
        self.rows_per_message = max(1, limits.values_per_message // width)
        self.last_input = spec.clock.started_at
        self.output_values = 0
        """The values this request's input so far commits it to send (frames up to the
        end of its phonemes × channels; an interrupt's return comes on top): kept as the
        phonemes arrive, since the session reads it twice per message."""

    @property
    def id(self) -> str:
        return self.spec.id

    # ---- input ----------------------------------------------------------------------------

    def output_values_until(self, end_s: float) -> int:
        return frame_count(end_s, self.spec.fps) * self.spec.profile.n_channels

    def add_phonemes(
        self,
        items: Sequence[PhonemeItem],
        now: float,
        session_max_values: int | None = None,
        others: int = 0,
    ) -> list[Outgoing]:
        """Take the next phonemes; the connection may send ``session_max_values`` values
        (None: no limit), of which its other requests hold ``others``."""
        self._check_count(len(items), "items")
        if len(items) == 1:  # as a TTS streams them, one per message
            spans: Sequence[PhonemeSpan] = (self._span(items[0], 0, self.phonemes_end),)
        else:
            spans = [
                self._span(item, index, self.phonemes_end if index == 0 else None)
                for index, item in enumerate(items)
            ]
        self._check_output(spans[-1].end, session_max_values, others)
        # Normalized here, at the edge (``_span``): the engine takes them as they are.
        self._feed(NormalizedSpans(spans), None, INVALID_REQUEST)
        return self._took(spans, now)

    def add_speech(
        self,
        spans: Sequence[PhonemeSpan],
        speech: Audio,
        now: float,
        session_max_values: int | None = None,
        others: int = 0,
    ) -> list[Outgoing]:
        """Take spoken text: its canonical ``spans``, contiguous from the end of the input so
        far, and ``speech``, the audio that says them, continuing the request's audio. The
        engine gets both in one call, so a model that hears and reads is driven by both."""
        self._check_count(len(spans), "text")
        for span in spans:
            self._check_end(span.end, "text")
        self._check_output(spans[-1].end, session_max_values, others)
        self._check_audio(speech.sample_rate, speech.duration)
        self._feed(list(spans), speech if self.spec.uses_audio else None, INVALID_REQUEST)
        self.audio_rate = speech.sample_rate
        self.audio_s += speech.duration
        return self._took(spans, now)

    def add_spans(
        self,
        spans: Sequence[PhonemeSpan],
        now: float,
        session_max_values: int | None = None,
        others: int = 0,
    ) -> list[Outgoing]:
        """Take canonical ``spans`` derived from word timings, contiguous from the end of the
        input so far; the limits as ``add_phonemes``."""
        if not spans:
            return []
        self._check_count(len(spans), "timings")
        for span in spans:
            self._check_end(span.end, "timings")
        self._check_output(spans[-1].end, session_max_values, others)
        self._feed(list(spans), None, INVALID_REQUEST)
        return self._took(spans, now)

    def _took(self, spans: Sequence[PhonemeSpan], now: float) -> list[Outgoing]:
        """The frames the engine released after taking ``spans``."""
        self.n_phonemes += len(spans)
        for span in spans:
            self.ends.append(span.end)
        self.phonemes_end = spans[-1].end
        self.output_values = self.output_values_until(self.phonemes_end)
        self.coverage.advance(self._covered_until(), now)
        return self._emit(self.synthesizer.frames(), now)

    def _check_count(self, count: int, where: str) -> None:
        if self.n_phonemes + count > self.limits.max_phonemes:
            raise RequestError(
                f"the request would hold {self.n_phonemes + count} phonemes; the server "
                f"allows {self.limits.max_phonemes} per request",
                code=TOO_MANY_PHONEMES,
                where=where,
                details={"max_phonemes": self.limits.max_phonemes},
            )

    def _span(self, item: PhonemeItem, index: int, previous_end: float | None) -> PhonemeSpan:
        """Item ``index`` of a ``phonemes`` message as a canonical span (its ``where`` is
        spelled only for an error)."""
        if previous_end is not None and item.start < previous_end - TIME_TOLERANCE_S:
            raise RequestError(
                f"starts at {item.start} s, before the previous phoneme of this "
                f"request ends at {previous_end} s",
                code=NON_MONOTONIC_TIMES,
                where=f"items[{index}].start",
            )
        phoneme = self._normalized(item.phoneme, index)
        if item.emotion is not None and item.emotion not in EMOTIONS:
            raise RequestError(
                f"unknown emotion {item.emotion!r}; known: {', '.join(EMOTIONS)}",
                code=UNKNOWN_EMOTION,
                where=f"items[{index}].emotion",
            )
        if not self._ends_within(item.end):
            self._check_end(item.end, f"items[{index}].end")
        return PhonemeSpan(phoneme, item.start, item.end, item.emotion)

    def _normalized(self, label: str, index: int) -> str:
        try:
            return normalize_phoneme(label, self.spec.phoneme_source, f"items[{index}].phoneme")
        except LipstreamError as error:
            raise RequestError(
                error.message, code=protocol_code(error, UNKNOWN_PHONEME), where=error.where
            ) from None

    def _ends_within(self, end: float) -> bool:
        """Input ending at ``end`` stays within the server's frames and seconds per request."""
        longest = self.limits.max_seconds
        return frame_count(end, self.spec.fps) <= self.limits.max_frames and (
            longest is None or end <= longest + TIME_TOLERANCE_S
        )

    def _check_end(self, end: float, where: str) -> None:
        """INVALID_TIMES for input ending beyond the server's frames or seconds per request."""
        if frame_count(end, self.spec.fps) > self.limits.max_frames:
            raise RequestError(
                f"ends at {end} s, beyond the server's limit of {self.limits.max_frames} "
                f"frames per request at {self.spec.fps:g} fps",
                code=INVALID_TIMES,
                where=where,
                details={"max_frames": self.limits.max_frames},
            )
        longest = self.limits.max_seconds
        if longest is not None and end > longest + TIME_TOLERANCE_S:
            raise RequestError(
                f"ends at {end} s, beyond the server's limit of {longest:g} s per request",
                code=INVALID_TIMES,
                where=where,
                details={"max_request_s": longest},
            )

    def _check_output(self, end_s: float, session_max_values: int | None, others: int) -> None:
        """OUTPUT_TOO_LARGE if input up to ``end_s`` would commit this request to more output
        values than its limit, or the connection (whose other requests hold ``others``) to
        more than ``session_max_values``."""
        values = self.output_values_until(end_s)
        limit = self.limits.max_values
        if limit is not None and values > limit:
            raise RequestError(
                f"{self._made(end_s, values)}, beyond the server's limit of {limit} values "
                "per request",
                code=OUTPUT_TOO_LARGE,
                where="items",
                details={"max_request_values": limit, "values": values},
            )
        if session_max_values is not None and others + values > session_max_values:
            raise RequestError(
                f"{self._made(end_s, values)}; with the {others} values of the connection's "
                f"other requests that exceeds the server's limit of {session_max_values} values "
                "per connection",
                code=OUTPUT_TOO_LARGE,
                where="items",
                details={"max_session_values": session_max_values, "values": others + values},
            )

    def _made(self, end_s: float, values: int) -> str:
        width = self.spec.profile.n_channels
        return (
            f"input up to {end_s:g} s makes {values // width} frames of {width} channels, "
            f"{values} values"
        )

    def add_audio(self, chunk: AudioChunk, now: float) -> list[Outgoing]:
        self._check_audio(chunk.sample_rate, chunk.duration)
        self.audio_rate = chunk.sample_rate
        self.audio_s += chunk.duration
        if not self.spec.uses_audio:
            return []
        self._feed([], Audio.from_pcm16(chunk.pcm16, chunk.sample_rate), INVALID_AUDIO)
        self.coverage.advance(self._covered_until(), now)
        return self._emit(self.synthesizer.frames(), now)

    def _check_audio(self, sample_rate: int, duration: float) -> None:
        """INVALID_AUDIO for audio at another rate than the request's, or beyond its limit."""
        if self.audio_rate is not None and sample_rate != self.audio_rate:
            raise RequestError(
                f"{sample_rate} Hz follows audio at {self.audio_rate} Hz in this request",
                code=INVALID_AUDIO,
                where="sample_rate",
            )
        limit_s = self.limits.max_frames / self.spec.fps
        if self.limits.max_seconds is not None:
            limit_s = min(limit_s, self.limits.max_seconds)
        if self.audio_s + duration > limit_s:
            raise RequestError(
                f"the request's audio would exceed the server's limit of {limit_s:g} s",
                code=INVALID_AUDIO,
                where="pcm16",
            )

    def _covered_until(self) -> float:
        if self.spec.uses_audio and self.audio_rate is not None:
            return min(self.phonemes_end, self.audio_s) if self.n_phonemes else self.audio_s
        return self.phonemes_end

    def _input_end(self) -> float:
        """Where the input ends: its phonemes', or an audio-only request's audio."""
        if not self.n_phonemes and self.spec.audio_only and self.audio_rate is not None:
            return self.audio_s
        return self.phonemes_end

    def _check_drivable(self) -> None:
        """AUDIO_ONLY_UNSUPPORTED for audio without phonemes to a model that needs phonemes."""
        if not self.n_phonemes and self.audio_rate is not None and not self.spec.audio_only:
            raise RequestError(
                f"the request sent audio and no phonemes, but engine {self.spec.engine}'s "
                "model cannot be driven by audio alone; send phonemes with the audio",
                code=AUDIO_ONLY_UNSUPPORTED,
                where="phonemes",
            )

    def _feed(self, spans: Sequence[PhonemeSpan], audio: Audio | None, fallback: str) -> None:
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
        self._check_drivable()
        blocks = self._emit(self._finish(), now)
        blocks += self._send(self._settling(), now)
        return blocks + [self._done("end", self.next_frame)]

    def _settling(self) -> np.ndarray:
        """The frames after the last one sent that take the face to rest (none when no
        frame was sent: the face never left rest)."""
        if self.next_frame == 0:
            return self._no_rows()
        face = np.asarray(self.tail.row(self.next_frame - 1), dtype=np.float64)
        steps = max(1, settle_frames(self.limits.default_return_ms, self.spec.fps))
        weights = _smoothstep(np.arange(1, steps + 1) / steps)
        rows: np.ndarray = face + (self.spec.rest - face) * weights[:, None]
        return np.asarray(rows, dtype=np.float32)

    def cancel(self) -> list[Outgoing]:
        return [self._done("cancel", self.next_frame)]

    def interrupt(self, at: float, return_ms: float | None, now: float) -> list[Outgoing]:
        fps = self.spec.fps
        cut = min(at, self._input_end())
        first_return = max(frames_before(cut, fps), self.tail.oldest)
        base = self.next_frame
        final = self._finish()
        unsent = self.spec.profile.apply(final) if len(final) else self._no_rows()
        blocks = self._send(unsent[: max(0, first_return - base)], now)
        face = self._face(first_return, base, unsent)
        steps = settle_frames(
            self.limits.default_return_ms if return_ms is None else return_ms, fps
        )
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
        return np.asarray(self.tail.row(index), dtype=np.float64)

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
        self.tail.extend(rows)
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
            if self.seq > MAX_SEQ:
                raise RequestError(
                    f"the request's next frames block would be numbered past the protocol's "
                    f"bound of {MAX_SEQ}",
                    code=OUTPUT_TOO_LARGE,
                    where="seq",
                    details={"max_seq": MAX_SEQ},
                )
            if chunk.dtype is _LITTLE_FLOAT32:  # as the profile leaves them: bytes in C order
                data = chunk.tobytes()
            else:
                data = np.ascontiguousarray(chunk, dtype="<f4").tobytes()
            frames = Frames(spec.id, self.seq, index, spec.fps, spec.profile.n_channels, data)
            self.seq += 1
            blocks.append(Outgoing(frames, spec.clock, received if received is not None else now))
        return blocks

    def _done(self, reason: DoneReason, frames: int) -> Outgoing:
        stats = DoneStats(frames=frames, engine=json_safe(self.synthesizer.stats))
        return Outgoing(Done(self.spec.id, stats, reason), self.spec.clock)


def settle_frames(return_ms: float, fps: float) -> int:
    """The frames a return to rest over ``return_ms`` takes after the face it starts from."""
    return max(0, math.ceil(return_ms / 1000.0 * fps - TIME_TOLERANCE_S))


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
