"""Typed messages of the lipstream wire protocol, version 1.

Sketch: one frozen dataclass per message ``type``. A client opens requests
with ``Start``, feeds ``Phonemes`` (and optionally ``AudioChunk``), ``Text``
for the server to speak, or ``Words``, a TTS's word or character timings, and
closes them with ``End``, ``Cancel`` or ``Interrupt``; the server answers with
``Ready``, a stream of ``Frames`` (and, for ``Text``, the speech as
``AudioChunk``s with their ``start``) and one ``Done``, or an ``ErrorMessage``.
Requests are multiplexed on one connection by their ``id``.

Times are seconds on the utterance clock (frame i is at i / fps seconds),
durations given in milliseconds say so in their name (``_ms``). Binary
payloads stay ``bytes`` (float32 little-endian frames, PCM16 little-endian
audio), so this module needs neither numpy nor I/O. The classes do not
validate; ``codec.encode`` and ``codec.decode`` do (see ``validate``).
"""

from __future__ import annotations

import sys
from array import array
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import ClassVar, Literal, TypeAlias

from .float32 import FLOAT32_BYTES, pack_float32, split_rows, unpack_float32

PROTOCOL_VERSION = 1

MIN_FPS = 1.0
MAX_FPS = 1000.0
DEFAULT_FPS = 60.0
MAX_ID_LENGTH = 128
MAX_NAME_LENGTH = 128
MAX_PHONEME_LENGTH = 32
MAX_EMOTION_LENGTH = 32
MAX_PHONEME_SOURCE_LENGTH = 32
MAX_CHANNELS = 1024
MAX_MAP_ENTRIES = 256
MAX_JSON_DEPTH = 16
MAX_ERROR_MESSAGE_LENGTH = 4096
MAX_ERROR_CODE_LENGTH = 64
MAX_LATENCY_BUDGET_MS = 60_000.0
MAX_RETURN_MS = 10_000.0
MAX_TIME_S = 86_400.0
MIN_SAMPLE_RATE = 8_000
MAX_SAMPLE_RATE = 192_000
MAX_INTEGER = 2**53 - 1
MAX_SEQ = 2**31 - 1
"""The largest ``seq`` of a ``frames`` block, and of ``resume.seq``: a bound far above any
request's blocks that leaves a resumed request room to number its own."""
MAX_VOICE_LENGTH = 64
MIN_RATE_WPM = 80
MAX_RATE_WPM = 450
PCM16_BYTES = 2

Encoding = Literal["msgpack", "json"]
Sender = Literal["client", "server"]
ENCODINGS: tuple[Encoding, ...] = ("msgpack", "json")
Naming = Literal["arkit", "livelink", "suffix_lr"]
VisemeSet = Literal["oculus15", "preston-blair"]
DoneReason = Literal["end", "cancel", "interrupt"]
NAMINGS: tuple[Naming, ...] = ("arkit", "livelink", "suffix_lr")
VISEME_SETS: tuple[VisemeSet, ...] = ("oculus15", "preston-blair")
DONE_REASONS: tuple[DoneReason, ...] = ("end", "cancel", "interrupt")

JsonValue: TypeAlias = None | bool | int | float | str | list["JsonValue"] | dict[str, "JsonValue"]
JsonMap: TypeAlias = Mapping[str, JsonValue]


def _empty_map() -> dict[str, JsonValue]:
    return {}


@dataclass(frozen=True, slots=True)
class ChannelTransform:
    """Output value = clamp(value * multiplier + offset) to ``clamp`` = (low, high) if given."""

    multiplier: float = 1.0
    offset: float = 0.0
    clamp: tuple[float, float] | None = None

    def apply(self, value: float) -> float:
        result = value * self.multiplier + self.offset
        if self.clamp is not None:
            result = min(max(result, self.clamp[0]), self.clamp[1])
        return result


@dataclass(frozen=True, slots=True)
class OutputProfile:
    """How a request's frames are named, chosen and scaled.

    ``naming`` renames the model's ARKit channels (None keeps ARKit);
    ``visemes`` replaces them by a viseme set (then ``naming`` must be None);
    ``retarget`` names a rig cross-mapping whose controls replace them (then
    ``naming`` and ``visemes`` must be None); ``channels`` picks and orders a
    subset, and ``transforms`` maps an output channel name to its
    ``ChannelTransform``. Names use the output naming.
    """

    naming: Naming | None = None
    channels: tuple[str, ...] | None = None
    transforms: Mapping[str, ChannelTransform] = field(default_factory=dict)
    visemes: VisemeSet | None = None
    retarget: str | None = None


@dataclass(frozen=True, slots=True)
class Resume:
    """A ``start`` that continues a request an earlier connection lost.

    The client already holds the request's frames ``0 .. frames - 1`` and its
    ``frames`` blocks ``0 .. seq - 1``; it re-sends the request's whole input
    after this ``start``. The server sends only the frames from index ``frames``
    on, numbering their blocks from ``seq``. ``fidelity`` is the rung the first
    ``ready`` named, so that the frames are those of the same rung. ``audio`` is
    the number of ``audio`` messages the client holds (the speech the server sent
    for the request's ``text``): the server sends its speech from the next one on.
    """

    frames: int
    seq: int
    fidelity: str | None = None
    audio: int = 0


@dataclass(frozen=True, slots=True)
class Start:
    """Open request ``id``: synthesize ``character``'s face with ``engine`` at ``fps`` Hz.

    Give either ``channels`` (a subset in ARKit naming) or a full ``output``
    profile, not both; with neither, the character's preset profile applies.
    ``latency_budget_ms`` bounds the time from receiving the input that
    covers t to sending the frame for t. ``options`` go to the engine.
    ``phoneme_source`` names the notation of the phoneme labels (e.g.
    ``arpabet``, ``espeak``, ``ipa``); None reads them with the server's
    automatic detection. ``resume`` continues a request a lost connection cut off.
    """

    type: ClassVar[str] = "start"
    v: ClassVar[int] = PROTOCOL_VERSION

    id: str
    engine: str
    character: str
    fps: float = DEFAULT_FPS
    channels: tuple[str, ...] | None = None
    output: OutputProfile | None = None
    emotion: str | None = None
    latency_budget_ms: float | None = None
    options: JsonMap = field(default_factory=_empty_map)
    phoneme_source: str | None = None
    resume: Resume | None = None


@dataclass(frozen=True, slots=True)
class PhonemeItem:
    """One phoneme over [start, end) seconds, absolute on the utterance clock."""

    phoneme: str
    start: float
    end: float
    emotion: str | None = None


@dataclass(frozen=True, slots=True)
class Phonemes:
    """The next phonemes of request ``id``, in order and not overlapping earlier ones."""

    type: ClassVar[str] = "phonemes"
    v: ClassVar[int] = PROTOCOL_VERSION

    id: str
    items: tuple[PhonemeItem, ...]


@dataclass(frozen=True, slots=True)
class AudioChunk:
    """The next mono audio of request ``id``: ``pcm16`` signed 16-bit little-endian samples.

    From a client, chunks are contiguous from t = 0 at one ``sample_rate`` (Hz) per
    request. From the server, a chunk is speech it synthesized for a ``Text``, and
    ``start`` says where on the utterance clock (seconds) it begins.
    """

    type: ClassVar[str] = "audio"
    v: ClassVar[int] = PROTOCOL_VERSION

    id: str
    sample_rate: int
    pcm16: bytes
    start: float | None = None

    @property
    def n_samples(self) -> int:
        return len(self.pcm16) // PCM16_BYTES

    @property
    def duration(self) -> float:
        """Seconds of audio in this chunk."""
        return self.n_samples / self.sample_rate

    def samples(self) -> list[int]:
        """The samples as ints in [-32768, 32767], shape (n_samples,)."""
        values = array("h")
        values.frombytes(self.pcm16[: self.n_samples * PCM16_BYTES])
        if sys.byteorder == "big":
            values.byteswap()
        return values.tolist()

    @property
    def end(self) -> float | None:
        """Where the chunk ends on the utterance clock, when it says where it starts."""
        return None if self.start is None else self.start + self.duration

    @classmethod
    def from_samples(cls, id: str, sample_rate: int, samples: Sequence[int]) -> AudioChunk:
        """Pack int samples in [-32768, 32767] (OverflowError outside) as PCM16 little-endian."""
        values = array("h", samples)
        if sys.byteorder == "big":
            values.byteswap()
        return cls(id, sample_rate, values.tobytes())


@dataclass(frozen=True, slots=True)
class Text:
    """Text for the server to speak as request ``id``'s next input, instead of phonemes.

    The server speaks it with espeak-ng (``lang``: an espeak-ng language such as
    ``de`` or ``cmn``, and then ``voice`` a voice variant such as ``f3``; without
    ``lang``, ``voice`` is a whole espeak-ng voice name; ``rate`` in words per minute;
    None: the server's defaults) from the end of the request's input so far, sends
    the speech back as ``AudioChunk``s with their ``start``, and feeds the engine
    the phonemes espeak-ng spoke.
    """

    type: ClassVar[str] = "text"
    v: ClassVar[int] = PROTOCOL_VERSION

    id: str
    text: str
    voice: str | None = None
    rate: int | None = None
    lang: str | None = None


TIMING_FORMATS: tuple[str, ...] = ("auto", "words", "elevenlabs", "azure", "polly", "ipa")


@dataclass(frozen=True, slots=True)
class Words:
    """A TTS's timings for request ``id``'s next input, instead of phonemes: words,
    characters, visemes or phonemes in one of ``TIMING_FORMATS`` (``auto``: detected).

    ``timings`` is the provider's own JSON value (or JSON lines as a string, as Polly
    writes them); ``offset`` (seconds) is added to every time in it, for providers whose
    chunks count from the chunk's start. The server gives the words their phonemes
    (CMUdict, else espeak-ng ``voice``) and spreads them with the character's duration
    model; a word that may continue in the next message is held until it comes or the
    request ends.
    """

    type: ClassVar[str] = "words"
    v: ClassVar[int] = PROTOCOL_VERSION

    id: str
    timings: JsonValue
    format: str = "auto"
    offset: float = 0.0
    voice: str | None = None


@dataclass(frozen=True, slots=True)
class End:
    """No more input for request ``id``: finish its frames, then send ``done``."""

    type: ClassVar[str] = "end"
    v: ClassVar[int] = PROTOCOL_VERSION

    id: str


@dataclass(frozen=True, slots=True)
class Cancel:
    """Abandon request ``id`` now: no more frames, ``done`` with reason ``cancel`` follows."""

    type: ClassVar[str] = "cancel"
    v: ClassVar[int] = PROTOCOL_VERSION

    id: str


@dataclass(frozen=True, slots=True)
class Interrupt:
    """Cut request ``id`` off at ``at`` seconds; the face returns to rest over ``return_ms``.

    Frames before ``at`` stand; None for ``return_ms`` takes the server's default.
    """

    type: ClassVar[str] = "interrupt"
    v: ClassVar[int] = PROTOCOL_VERSION

    id: str
    at: float
    return_ms: float | None = None


@dataclass(frozen=True, slots=True)
class Ready:
    """Request ``id`` is running with these resolved parameters.

    ``fidelity`` names the engine rung chosen for the latency budget,
    ``lookahead_ms`` is how far input must run ahead of a frame before it is
    final, and ``channels`` names the columns of every ``Frames`` row.
    """

    type: ClassVar[str] = "ready"
    v: ClassVar[int] = PROTOCOL_VERSION

    id: str
    engine: str
    character: str
    fps: float
    channels: tuple[str, ...]
    lookahead_ms: float
    fidelity: str
    emotion: str | None = None
    latency_budget_ms: float | None = None
    options: JsonMap = field(default_factory=_empty_map)
    phoneme_source: str | None = None


@dataclass(frozen=True, slots=True)
class Frames:
    """A block of final frames of request ``id``.

    ``data`` is float32 little-endian, row-major, shape (n_frames, n_channels);
    row r is frame ``first_frame + r``, at ``(first_frame + r) / fps`` seconds.
    ``seq`` counts the request's ``frames`` messages from 0.
    """

    type: ClassVar[str] = "frames"
    v: ClassVar[int] = PROTOCOL_VERSION

    id: str
    seq: int
    first_frame: int
    fps: float
    n_channels: int
    data: bytes

    @property
    def n_frames(self) -> int:
        return len(self.data) // (FLOAT32_BYTES * self.n_channels) if self.n_channels else 0

    @property
    def end_frame(self) -> int:
        """Index one past the last frame of this block."""
        return self.first_frame + self.n_frames

    def rows(self) -> list[list[float]]:
        """The values as (n_frames, n_channels) nested lists."""
        return split_rows(unpack_float32(self.data), self.n_channels)

    def times(self) -> list[float]:
        """Each row's time in seconds, shape (n_frames,)."""
        return [index / self.fps for index in range(self.first_frame, self.end_frame)]

    @classmethod
    def from_rows(
        cls, id: str, seq: int, first_frame: int, fps: float, rows: Sequence[Sequence[float]]
    ) -> Frames:
        """Pack (n_frames, n_channels) rows; ValueError if rows differ in length or are empty."""
        if not rows or not rows[0]:
            raise ValueError("frames need at least one row of at least one channel")
        width = len(rows[0])
        if any(len(row) != width for row in rows):
            raise ValueError(f"every row must have {width} values")
        return cls(
            id, seq, first_frame, fps, width, pack_float32([value for row in rows for value in row])
        )


@dataclass(frozen=True, slots=True)
class DoneStats:
    """Outcome of a request.

    ``frames`` sent; ``first_frame_latency_ms`` from receiving ``start`` to
    sending the first frame; ``max_lag_ms`` the longest time from receiving
    the input covering t to sending frame t (for ``text``, from when its speech
    was ready); ``budget_met`` whether that lag stayed within the latency
    budget (None without a budget); ``engine`` holds engine statistics (e.g.
    jumps, cost); ``speech_synthesis_ms`` the time the server spent speaking
    the request's ``text`` messages (None without text).
    """

    frames: int
    first_frame_latency_ms: float | None = None
    max_lag_ms: float | None = None
    budget_met: bool | None = None
    engine: JsonMap = field(default_factory=_empty_map)
    speech_synthesis_ms: float | None = None


@dataclass(frozen=True, slots=True)
class Done:
    """Request ``id`` is over (``reason``: end, cancel or interrupt); its id is free again."""

    type: ClassVar[str] = "done"
    v: ClassVar[int] = PROTOCOL_VERSION

    id: str
    stats: DoneStats
    reason: DoneReason = "end"


@dataclass(frozen=True, slots=True)
class ErrorMessage:
    """An error with a stable ``code`` (see ``errors``), for request ``id`` or the connection.

    ``fatal`` means the request (or, with no id, the connection) has ended.
    ``details`` carries machine-readable extras, e.g. ``min_budget_ms``.
    """

    type: ClassVar[str] = "error"
    v: ClassVar[int] = PROTOCOL_VERSION

    code: str
    message: str
    id: str | None = None
    fatal: bool = False
    details: JsonMap = field(default_factory=_empty_map)


ClientMessage: TypeAlias = Start | Phonemes | AudioChunk | Text | Words | End | Cancel | Interrupt
ServerMessage: TypeAlias = Ready | Frames | AudioChunk | Done | ErrorMessage
Message: TypeAlias = ClientMessage | ServerMessage

CLIENT_MESSAGE_TYPES: dict[str, type[ClientMessage]] = {
    cls.type: cls for cls in (Start, Phonemes, AudioChunk, Text, Words, End, Cancel, Interrupt)
}
SERVER_MESSAGE_TYPES: dict[str, type[ServerMessage]] = {
    cls.type: cls for cls in (Ready, Frames, AudioChunk, Done, ErrorMessage)
}
MESSAGE_TYPES: dict[str, type[Message]] = {**CLIENT_MESSAGE_TYPES, **SERVER_MESSAGE_TYPES}
