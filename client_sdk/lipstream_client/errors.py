"""Error codes and WebSocket close codes of the lipstream wire protocol, version 1.

Sketch: every ``error`` message carries one stable string ``code`` from this
module, and every server-initiated close uses one ``CloseCode``. The codec
(``lipstream_client.codec``) produces the *structural* codes as a
``ProtocolError`` value; the server adds the *semantic* ones (unknown engine,
session state, limits). ``ERROR_CODES`` describes each code once, and
``docs/reference/protocol.md`` lists the same table.

``fatal`` in an error means the error's scope is over: with an ``id``, that
request has ended (no more frames or ``done`` for it, and the id is free);
without one, the server closes the connection right after the error with the
code's close code.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Literal

from .messages import MAX_ERROR_MESSAGE_LENGTH, ErrorMessage

# Structural errors, found by the codec while decoding one message.
MALFORMED = "malformed"
MESSAGE_TOO_LARGE = "message_too_large"
INVALID_MESSAGE = "invalid_message"
UNSUPPORTED_VERSION = "unsupported_version"
UNKNOWN_TYPE = "unknown_type"
INVALID_TIMES = "invalid_times"
NON_MONOTONIC_TIMES = "non_monotonic_times"
INVALID_AUDIO = "invalid_audio"
INVALID_FRAMES = "invalid_frames"

# Semantic errors, found by the server against its models and session state.
UNKNOWN_ENGINE = "unknown_engine"
UNKNOWN_CHARACTER = "unknown_character"
UNKNOWN_PHONEME = "unknown_phoneme"
UNKNOWN_PHONEME_SOURCE = "unknown_phoneme_source"
UNKNOWN_EMOTION = "unknown_emotion"
UNKNOWN_CHANNEL = "unknown_channel"
UNKNOWN_RETARGET = "unknown_retarget"
INVALID_REQUEST = "invalid_request"
UNKNOWN_REQUEST = "unknown_request"
DUPLICATE_REQUEST = "duplicate_request"
REQUEST_FINISHED = "request_finished"
TOO_MANY_PHONEMES = "too_many_phonemes"
TOO_MANY_REQUESTS = "too_many_requests"
BUDGET_INFEASIBLE = "budget_infeasible"
CPU_BUDGET_EXCEEDED = "cpu_budget_exceeded"
SEARCH_TOO_LARGE = "search_too_large"
SEARCH_TIMEOUT = "search_timeout"
OUTPUT_TOO_LARGE = "output_too_large"
INPUT_TOO_LARGE = "input_too_large"
AUDIO_ONLY_UNSUPPORTED = "audio_only_unsupported"
REQUEST_TIMEOUT = "request_timeout"
EMPTY_TEXT = "empty_text"
TEXT_TOO_LONG = "text_too_long"
UNSPEAKABLE_TEXT = "unspeakable_text"
SPEECH_FAILED = "speech_failed"
EMPTY_TIMINGS = "empty_timings"
UNKNOWN_TIMING_FORMAT = "unknown_timing_format"
MISMATCHED_WORDS = "mismatched_words"
UNKNOWN_LANGUAGE = "unknown_language"
UNMAPPED_PHONEME = "unmapped_phoneme"
RESUME_MISMATCH = "resume_mismatch"

# Connection-level errors: the server closes the connection after sending them.
RATE_LIMITED = "rate_limited"
IDLE_TIMEOUT = "idle_timeout"
SERVER_BUSY = "server_busy"
TOO_MANY_CLIENT_CONNECTIONS = "too_many_client_connections"
SHUTTING_DOWN = "shutting_down"
STARTING = "starting"
UNAUTHORIZED = "unauthorized"
ORIGIN_NOT_ALLOWED = "origin_not_allowed"
SLOW_CONSUMER = "slow_consumer"
INTERNAL_ERROR = "internal_error"


class CloseCode(IntEnum):
    """WebSocket close codes (RFC 6455 section 7.4) as lipstream uses them."""

    NORMAL = 1000
    GOING_AWAY = 1001
    POLICY_VIOLATION = 1008
    MESSAGE_TOO_BIG = 1009
    INTERNAL_ERROR = 1011
    SERVICE_RESTART = 1012
    TRY_AGAIN_LATER = 1013


RETRYABLE_CLOSE_CODES = frozenset(
    {CloseCode.GOING_AWAY, CloseCode.SERVICE_RESTART, CloseCode.TRY_AGAIN_LATER}
)

CLOSE_CODE_MEANINGS: dict[CloseCode, str] = {
    CloseCode.NORMAL: "normal closure, by either side; also after an idle timeout",
    CloseCode.GOING_AWAY: "the server is draining for shutdown; in-flight requests have finished",
    CloseCode.POLICY_VIOLATION: "authentication, Origin, rate limit or slow-consumer policy",
    CloseCode.MESSAGE_TOO_BIG: "a message exceeded the server's maximum message size",
    CloseCode.INTERNAL_ERROR: "an unexpected server fault; the server keeps running",
    CloseCode.SERVICE_RESTART: "sent by the ASGI server itself when it stops without a drain",
    CloseCode.TRY_AGAIN_LATER: "the server is at its capacity (sessions, load or memory); "
    "retry after details.retry_after_ms",
}

_CLIPPED = "..."

Scope = Literal["message", "request", "connection"]
Origin = Literal["codec", "server"]


@dataclass(frozen=True, slots=True)
class ErrorCodeInfo:
    """What a code means, who detects it, what it ends, and the close code that follows.

    A codec error of ``request`` scope ends the request only when the rejected
    message named a readable id; otherwise only that message is dropped.
    """

    meaning: str
    origin: Origin
    scope: Scope
    close_code: CloseCode | None = None


ERROR_CODES: dict[str, ErrorCodeInfo] = {
    MALFORMED: ErrorCodeInfo(
        "not decodable: invalid msgpack or JSON, trailing bytes, msgpack ext types, non-string "
        "or duplicate map keys, invalid UTF-8, or the wrong frame type for the encoding",
        "codec",
        "message",
    ),
    MESSAGE_TOO_LARGE: ErrorCodeInfo(
        "the message exceeds the maximum message size",
        "codec",
        "connection",
        CloseCode.MESSAGE_TOO_BIG,
    ),
    INVALID_MESSAGE: ErrorCodeInfo(
        "not an object, or a field is missing, unexpected, of the wrong type or out of range",
        "codec",
        "request",
    ),
    UNSUPPORTED_VERSION: ErrorCodeInfo(
        "the message's `v` is a protocol version this peer does not speak", "codec", "request"
    ),
    UNKNOWN_TYPE: ErrorCodeInfo(
        "the message's `type` is unknown, or not one this peer accepts", "codec", "request"
    ),
    INVALID_TIMES: ErrorCodeInfo(
        "a time is not finite, negative, or a phoneme's end is not after its start",
        "codec",
        "request",
    ),
    NON_MONOTONIC_TIMES: ErrorCodeInfo(
        "a phoneme starts before the previous one ends, within a message or across messages",
        "codec",
        "request",
    ),
    INVALID_AUDIO: ErrorCodeInfo(
        "PCM16 data of odd length, invalid base64, or a sample rate that changes mid-request",
        "codec",
        "request",
    ),
    INVALID_FRAMES: ErrorCodeInfo(
        "frames data does not fit n_channels, or holds a value that is not a finite float32",
        "codec",
        "request",
    ),
    UNKNOWN_ENGINE: ErrorCodeInfo("no engine of that name is loaded", "server", "request"),
    UNKNOWN_CHARACTER: ErrorCodeInfo(
        "no model of that character is loaded for the engine", "server", "request"
    ),
    UNKNOWN_PHONEME: ErrorCodeInfo(
        "a phoneme label is not in the phoneme set", "server", "request"
    ),
    UNKNOWN_PHONEME_SOURCE: ErrorCodeInfo(
        "`phoneme_source` names no notation the server reads", "server", "request"
    ),
    UNKNOWN_EMOTION: ErrorCodeInfo("an emotion the engine does not know", "server", "request"),
    UNKNOWN_CHANNEL: ErrorCodeInfo(
        "an output channel, subset or transform names a channel the rig lacks", "server", "request"
    ),
    UNKNOWN_RETARGET: ErrorCodeInfo(
        "output.retarget names no rig preset or stored map the model has; the message lists them",
        "server",
        "request",
    ),
    INVALID_REQUEST: ErrorCodeInfo(
        "the request is well formed but its values are not acceptable to the engine "
        "(fps, options, output profile)",
        "server",
        "request",
    ),
    UNKNOWN_REQUEST: ErrorCodeInfo(
        "a message names an id with no active request (for example before its `start`)",
        "server",
        "message",
    ),
    DUPLICATE_REQUEST: ErrorCodeInfo(
        "`start` reuses the id of an active request; that request continues", "server", "message"
    ),
    REQUEST_FINISHED: ErrorCodeInfo(
        "input arrived after the request's `end`; the request still completes", "server", "message"
    ),
    TOO_MANY_PHONEMES: ErrorCodeInfo(
        "the request exceeds the maximum number of phonemes per request", "server", "request"
    ),
    TOO_MANY_REQUESTS: ErrorCodeInfo(
        "the connection already has the maximum number of active requests", "server", "request"
    ),
    BUDGET_INFEASIBLE: ErrorCodeInfo(
        "no fidelity rung meets latency_budget_ms; details.min_budget_ms is the smallest "
        "feasible budget",
        "server",
        "request",
    ),
    EMPTY_TEXT: ErrorCodeInfo(
        "a `text` message holds nothing to speak (empty or only white space)", "server", "request"
    ),
    TEXT_TOO_LONG: ErrorCodeInfo(
        "a `text` message holds more characters than the server speaks at once "
        "(details.max_text_chars)",
        "server",
        "request",
    ),
    UNSPEAKABLE_TEXT: ErrorCodeInfo(
        "espeak-ng said nothing for a `text` message, or a sound the phoneme set lacks",
        "server",
        "request",
    ),
    UNKNOWN_LANGUAGE: ErrorCodeInfo(
        "a `text` message's `lang` is no language espeak-ng speaks", "server", "request"
    ),
    UNMAPPED_PHONEME: ErrorCodeInfo(
        "espeak-ng spoke a phoneme (details.phoneme, in details.lang) that the articulatory "
        "feature table cannot read",
        "server",
        "request",
    ),
    SPEECH_FAILED: ErrorCodeInfo(
        "espeak-ng failed (crashed, timed out, or is missing) speaking a `text` message; "
        "the server keeps serving",
        "server",
        "request",
    ),
    EMPTY_TIMINGS: ErrorCodeInfo(
        "word, character, viseme or phoneme timings hold nothing to speak", "server", "request"
    ),
    UNKNOWN_TIMING_FORMAT: ErrorCodeInfo(
        "timings are in no format the server reads, or the named format does not fit them",
        "server",
        "request",
    ),
    MISMATCHED_WORDS: ErrorCodeInfo(
        "timed words do not match their characters or text (parallel arrays of different "
        "lengths, an entry that is not one character, a text offset that names other text)",
        "server",
        "request",
    ),
    CPU_BUDGET_EXCEEDED: ErrorCodeInfo(
        "the request's engine work used up the server's CPU budget per request",
        "server",
        "request",
    ),
    SEARCH_TOO_LARGE: ErrorCodeInfo(
        "the request holds more phonemes than an exponential search option allows "
        "(anime-graph's PQ-Matching: pq_window × phonemes at most 256)",
        "server",
        "request",
    ),
    SEARCH_TIMEOUT: ErrorCodeInfo(
        "the search ran past the request's own search budget (anime-graph's pq_budget_s)",
        "server",
        "request",
    ),
    AUDIO_ONLY_UNSUPPORTED: ErrorCodeInfo(
        "the request sent audio and no phonemes, but its model cannot be driven by audio alone",
        "server",
        "request",
    ),
    OUTPUT_TOO_LARGE: ErrorCodeInfo(
        "the request's output (frames up to the end of its input × channels) would exceed "
        "the per-request or per-connection maximum; details name the limit",
        "server",
        "request",
    ),
    INPUT_TOO_LARGE: ErrorCodeInfo(
        "holding the request's audio input (its speech features and a window of samples, "
        "and the chunk being taken in) would take the input all requests hold past the "
        "server's share of its memory ceiling; details name the sizes",
        "server",
        "request",
    ),
    REQUEST_TIMEOUT: ErrorCodeInfo(
        "no message for the request arrived within the request timeout", "server", "request"
    ),
    RESUME_MISMATCH: ErrorCodeInfo(
        "a resuming start names a fidelity rung this server's model lacks, so the frames the "
        "client holds cannot be continued, or a resume.seq that leaves too little room below "
        "the bound on seq for the blocks the request may send",
        "server",
        "request",
    ),
    RATE_LIMITED: ErrorCodeInfo(
        "the connection exceeded its message rate",
        "server",
        "connection",
        CloseCode.POLICY_VIOLATION,
    ),
    IDLE_TIMEOUT: ErrorCodeInfo(
        "no message arrived within the idle timeout and no request is active",
        "server",
        "connection",
        CloseCode.NORMAL,
    ),
    SERVER_BUSY: ErrorCodeInfo(
        "the server is at its capacity: its session cap, its measured load (event-loop lag "
        "or busy time) or its memory ceiling; details.retry_after_ms says when to retry. "
        "Refused for load, the upgrade gets HTTP 503 with this error as its JSON body. "
        "Refusing a `start` (memory), it ends only that request",
        "server",
        "connection",
        CloseCode.TRY_AGAIN_LATER,
    ),
    TOO_MANY_CLIENT_CONNECTIONS: ErrorCodeInfo(
        "the client's address holds the server's maximum of open connections, or opened "
        "WebSockets faster than its upgrade rate (details.reason: connections or "
        "upgrade_rate); refused before the upgrade with HTTP 503, this code in the JSON body "
        "and Retry-After",
        "server",
        "connection",
        CloseCode.TRY_AGAIN_LATER,
    ),
    SHUTTING_DOWN: ErrorCodeInfo(
        "the server is draining: new `start`s are refused (request scope) and the connection "
        "closes once its in-flight requests are done",
        "server",
        "connection",
        CloseCode.GOING_AWAY,
    ),
    STARTING: ErrorCodeInfo(
        "the server is starting up (building, loading or calibrating its models; GET /readyz "
        "names the phase): it serves no synthesis until /readyz answers 200. Retry then",
        "server",
        "connection",
        CloseCode.TRY_AGAIN_LATER,
    ),
    UNAUTHORIZED: ErrorCodeInfo(
        "missing or wrong bearer token", "server", "connection", CloseCode.POLICY_VIOLATION
    ),
    ORIGIN_NOT_ALLOWED: ErrorCodeInfo(
        "the Origin header is not in the allow-list",
        "server",
        "connection",
        CloseCode.POLICY_VIOLATION,
    ),
    SLOW_CONSUMER: ErrorCodeInfo(
        "the client read too slowly and the bounded send queue filled; the close reason "
        "carries this code (no error message can be queued)",
        "server",
        "connection",
        CloseCode.POLICY_VIOLATION,
    ),
    INTERNAL_ERROR: ErrorCodeInfo(
        "an unexpected server fault; with an id only that request ends",
        "server",
        "connection",
        CloseCode.INTERNAL_ERROR,
    ),
}


@dataclass(frozen=True, slots=True)
class ProtocolError:
    """Why a message was rejected, as a value (decoding returns it, never raises).

    ``where`` is the offending field's path inside the message (``items[2].end``)
    or None; ``id`` is the request id when the message named a readable one.
    """

    code: str
    message: str
    id: str | None = None
    fatal: bool = False
    where: str | None = None

    def __str__(self) -> str:
        location = f"{self.where}: " if self.where else ""
        return f"{location}{self.message} [{self.code}]"

    def to_message(self) -> ErrorMessage:
        """The ``error`` message that reports this to the peer, its text clipped to the
        protocol's limit (a rejected field name or value may be arbitrarily long)."""
        text = f"{self.where}: {self.message}" if self.where else self.message
        if len(text) > MAX_ERROR_MESSAGE_LENGTH:
            text = text[: MAX_ERROR_MESSAGE_LENGTH - len(_CLIPPED)] + _CLIPPED
        return ErrorMessage(self.code, text, self.id, self.fatal)


class EncodeError(ValueError):
    """``encode`` refused a message that its own decoder would reject."""

    def __init__(self, error: ProtocolError) -> None:
        self.error = error
        super().__init__(str(error))
