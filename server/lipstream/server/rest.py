"""``POST /v1/synthesize``: a whole utterance in, all its frames out, through the stream's code.

Sketch: the body, JSON or msgpack by ``Content-Type``, holds the fields of a
``start`` message plus one input: ``items`` (its phonemes, as in ``phonemes``) or
``words`` (a TTS's timings: the fields of a ``words`` message, ``{timings, format,
offset, voice}``), each with an optional ``audio`` (``{sample_rate, pcm16}`` as in
``audio``), or instead the fields of a ``text`` message (``text``, ``lang``, ``voice``,
``rate``), whose speech the answer carries as ``speech``, or a ``transcript`` of its
``audio`` (required then), whose phonemes the forced aligner finds (``align``: after the
start and the audio have passed the session's limits, in the synthesis pool, off the event
loop) and whose answer carries ``alignment: {confidence}``. The protocol
codec parses it, it is split into those protocol messages, each validated by
the codec as parsed (never re-encoded, so a number that overflows to infinity
is the codec's error, not a fault), and played
through a fresh ``Session`` (start, audio, phonemes or text, end) in the synthesis
thread pool. So the frames equal, value for value, what ``/v1/stream``
sends for the same request, since engines give the same frames for any
chunking of the input. The response, msgpack or JSON by ``Accept`` (default:
the request's type), carries ``ready``'s resolved parameters, every frame
(float32 little-endian ``bin`` in msgpack, rows of shortest float32 decimals
in JSON) and ``done``'s stats; with ``Accept: text/csv`` it is the frames
alone as the corpus frame CSV (``time`` and one column per output channel,
``%.6f``). Every answer is streamed (chunked transfer encoding), each
piece once the previous one is in the connection's buffer. A JSON answer's
numbers are encoded ``JSON_CHUNK_VALUES`` at a time in the synthesis pool,
so the JSON encoder (a C call that holds the GIL for its whole input:
seconds for a long answer at 1000 fps) never holds the event loop for more
than one piece, a client that reads slowly holds its rows as float32 (a
third of their JSON), not as text, and the bytes are exactly those of one
``json.dumps`` of the whole answer; a msgpack or CSV answer (milliseconds to
encode) is encoded whole in the pool and sent ``SLICE_BYTES`` at a time.
From the end of its synthesis until its last piece is handed to the
connection or its client is gone, an answer's held bytes (a JSON answer's
frames, a msgpack or CSV answer's encoding) count toward the memory
ceiling (``ServerState.answer_bytes``, ``lipstream_rest_answer_bytes``):
each new request is checked against the latest resident-memory figure
plus them, so a burst of answers left unread is refused before the next
sample could see it (bytes already in that figure count twice, the safe
side). Errors answer with an HTTP status and
``{"error": {"code", "message", "details"}}`` in the response's type (JSON
when CSV was asked for); above the memory ceiling (``overload``) the request
is refused before its body is read, with 503 ``server_busy``,
``details.retry_after_ms`` and ``Retry-After``.
"""

from __future__ import annotations

import asyncio
import base64
import json
import math
import time
from collections.abc import AsyncIterator, Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Literal

import msgpack
import numpy as np
from starlette.requests import Request
from starlette.responses import Response, StreamingResponse
from starlette.types import Receive, Scope, Send

from lipstream_client import (
    AudioChunk,
    Done,
    Encoding,
    End,
    ErrorMessage,
    Frames,
    Message,
    PhonemeItem,
    Phonemes,
    ProtocolError,
    Ready,
)
from lipstream_client.codec import parse_payload, payload_message
from lipstream_client.errors import (
    INTERNAL_ERROR,
    INVALID_MESSAGE,
    MALFORMED,
    MESSAGE_TOO_LARGE,
    SERVER_BUSY,
    UNAUTHORIZED,
)

from ..audio import Audio
from ..corpus.frames_csv import frames_csv_text
from ..errors import LipstreamError
from ..frontends.align_codes import EMPTY_TRANSCRIPT
from .admission import bearer_token, token_accepted
from .frames_wire import json_rows
from .load import MIB
from .session import Session
from .state import ServerState

if TYPE_CHECKING:
    from ..frontends.align import Alignment

REQUEST_ID = "synthesize"
START_FIELDS = (
    "engine",
    "character",
    "fps",
    "channels",
    "output",
    "emotion",
    "latency_budget_ms",
    "options",
    "phoneme_source",
)
TEXT_FIELDS = ("text", "lang", "voice", "rate")
BODY_FIELDS = (*START_FIELDS, "items", "words", "audio", "transcript", *TEXT_FIELDS)
INPUTS = ("items", "words", "text", "transcript")
MEDIA_TYPES: dict[str, Encoding] = {
    "application/json": "json",
    "application/msgpack": "msgpack",
    "application/x-msgpack": "msgpack",
    "application/vnd.msgpack": "msgpack",
}
RESPONSE_TYPES: dict[Encoding, str] = {"json": "application/json", "msgpack": "application/msgpack"}
CSV_TYPE = "text/csv"
ResponseFormat = Literal["json", "msgpack", "csv"]
STATUS = {
    MALFORMED: 400,
    INVALID_MESSAGE: 400,
    "invalid_times": 400,
    "non_monotonic_times": 400,
    "unknown_timing_format": 400,
    "mismatched_words": 400,
    "empty_timings": 400,
    "invalid_audio": 400,
    EMPTY_TRANSCRIPT: 400,
    "unsupported_version": 400,
    "unknown_type": 400,
    "unknown_engine": 404,
    "unknown_character": 404,
    MESSAGE_TOO_LARGE: 413,
    "input_too_large": 503,
    UNAUTHORIZED: 401,
    "unsupported_media_type": 415,
    "not_acceptable": 406,
    INTERNAL_ERROR: 500,
    SERVER_BUSY: 503,
}
UNPROCESSABLE = 422
JSON_CHUNK_VALUES = 4096  # numbers per piece of a streamed JSON answer: milliseconds of GIL
JSON_SEPARATORS = (",", ":")
SLICE_BYTES = 1 << 18  # a piece of a msgpack or CSV answer


class HttpError(Exception):
    """An error response: protocol-style ``code``, HTTP ``status``, ``details``."""

    def __init__(
        self,
        code: str,
        message: str,
        status: int | None = None,
        details: Mapping[str, Any] | None = None,
    ) -> None:
        super().__init__(message)
        self.code = code
        self.message = message
        self.status = status or STATUS.get(code, UNPROCESSABLE)
        self.details = dict(details or {})


@dataclass(frozen=True)
class Transcript:
    """The body's ``transcript``: what its audio says, aligned when the session has the audio."""

    text: str


BodyPart = Message | Transcript


@dataclass
class Synthesis:
    """What the session answered: ``ready``, the frame rows and ``done``; a transcript's
    alignment ``confidence``."""

    ready: Ready
    frames: np.ndarray
    done: Done
    speech: list[AudioChunk] = field(default_factory=list)
    confidence: float | None = None


async def synthesize(request: Request, state: ServerState) -> Response:
    """Handle one ``POST /v1/synthesize``."""
    started = time.perf_counter()
    response_encoding: ResponseFormat = "json"
    try:
        request_encoding = _request_encoding(request)
        response_encoding = _response_encoding(request, request_encoding)
        authorize(request, state)
        _admit(state)
        body = await read_body(request, state.settings.max_body_bytes)
        messages = _messages(_parse(body, request_encoding), request_encoding)
        loop = asyncio.get_running_loop()
        lane = state.speech.client(rest_client(request))
        if response_encoding == "json":
            result = await loop.run_in_executor(lane, _run, messages, state)
            response = _held_answer(
                _json_pieces(result, state), result.frames.nbytes, "json", state
            )
        else:
            whole = await loop.run_in_executor(lane, _answer, messages, state, response_encoding)
            response = _held_answer(_slices(whole), len(whole), response_encoding, state)
    except HttpError as error:
        state.metrics.errors.labels(error.code).inc()
        return error_response(error, "json" if response_encoding == "csv" else response_encoding)
    state.metrics.synthesize.observe(time.perf_counter() - started)
    return response


def rest_client(request: Request) -> tuple[str, str]:
    """The key a REST call takes its turns in the speech lane under: its client's address."""
    return ("rest", request.client.host if request.client is not None else "")


def _answer(messages: list[BodyPart], state: ServerState, encoding: ResponseFormat) -> bytes:
    """Synthesize and encode a msgpack or CSV answer (in the thread pool: both scale with
    the utterance; their encoders take milliseconds where JSON's takes seconds)."""
    result = _run(messages, state)
    if encoding == "csv":
        return frames_csv_text(result.frames, result.ready.channels, result.ready.fps).encode()
    body = _fields(result, "msgpack")
    body["data"] = np.ascontiguousarray(result.frames, dtype="<f4").tobytes()
    packed: bytes = msgpack.packb(body, use_bin_type=True)
    return packed


def _request_encoding(request: Request) -> Encoding:
    media = request.headers.get("content-type", "").split(";")[0].strip().lower()
    if media not in MEDIA_TYPES:
        raise HttpError(
            "unsupported_media_type",
            f"Content-Type must be one of {', '.join(MEDIA_TYPES)}, got {media or 'none'!r}",
        )
    return MEDIA_TYPES[media]


def _response_encoding(request: Request, default: Encoding) -> ResponseFormat:
    """The first acceptable type in ``Accept`` (quality factors > 0, in order)."""
    accept = request.headers.get("accept")
    if not accept:
        return default
    for part in accept.split(","):
        media, *parameters = (piece.strip().lower() for piece in part.split(";"))
        if any(
            parameter.replace(" ", "") in ("q=0", "q=0.0", "q=0.00", "q=0.000")
            for parameter in parameters
        ):
            continue
        if media in ("*/*", "application/*"):
            return default
        if media in MEDIA_TYPES:
            return MEDIA_TYPES[media]
        if media in (CSV_TYPE, "text/*"):
            return "csv"
    raise HttpError(
        "not_acceptable", "Accept must allow application/json, application/msgpack or text/csv"
    )


def _admit(state: ServerState) -> None:
    """503 ``server_busy`` while the server, with the frames of the answers still being
    sent, is above its memory ceiling (``overload``)."""
    refusal = state.overload.request_refusal(held_mb=state.answer_bytes / MIB)
    if refusal is not None:
        raise HttpError(refusal.code, refusal.message, details=refusal.details)


def authorize(request: Request, state: ServerState) -> None:
    token = bearer_token(request.headers.get("authorization"), request.scope["query_string"])
    if not token_accepted(token, state.settings.auth_tokens):
        raise HttpError(
            UNAUTHORIZED, "a valid bearer token is required (Authorization: Bearer <token>)"
        )


async def read_json_object(
    request: Request, limit: int, not_object: str = "invalid_request"
) -> dict[str, Any]:
    """The request's body, at most ``limit`` bytes, as a JSON object (an empty body: ``{}``);
    ``malformed`` when it is not JSON, ``not_object`` when it is not an object."""
    raw = await read_body(request, limit)
    try:
        parsed = json.loads(raw or b"{}")
    except (json.JSONDecodeError, UnicodeDecodeError) as error:
        raise HttpError("malformed", f"the body is not JSON: {error}") from error
    if not isinstance(parsed, dict):
        raise HttpError(not_object, "the body must be an object")
    return parsed


async def read_body(request: Request, limit: int) -> bytes:
    """The request's body; ``message_too_large`` past ``limit`` bytes, declared or read."""
    declared = request.headers.get("content-length")
    if declared is not None and declared.isdigit() and int(declared) > limit:
        raise _too_large(int(declared), limit)
    chunks: list[bytes] = []
    size = 0
    async for chunk in request.stream():
        size += len(chunk)
        if size > limit:
            raise _too_large(size, limit)
        chunks.append(chunk)
    return b"".join(chunks)


def _too_large(size: int, limit: int) -> HttpError:
    return HttpError(
        MESSAGE_TOO_LARGE,
        f"body of at least {size} bytes exceeds the limit of {limit} bytes",
        details={"max_body_bytes": limit},
    )


def _parse(body: bytes, encoding: Encoding) -> dict[str, Any]:
    parsed = parse_payload(body, encoding)
    if isinstance(parsed, ProtocolError):
        raise HttpError(parsed.code, f"the body is {parsed.message}")
    if not isinstance(parsed, dict):
        raise HttpError(INVALID_MESSAGE, "the body must be an object")
    unknown = sorted(str(key) for key in parsed if key not in BODY_FIELDS)
    if unknown:
        raise HttpError(
            INVALID_MESSAGE,
            f"unknown field(s) {', '.join(unknown)}; expected {', '.join(BODY_FIELDS)}",
        )
    inputs = [key for key in INPUTS if key in parsed]
    if len(inputs) != 1:
        raise HttpError(
            INVALID_MESSAGE,
            "items, words, text or transcript: give exactly one (the utterance's phonemes, a "
            "TTS's timings, a text for espeak-ng to speak, or the transcript of the audio)",
        )
    if "transcript" in parsed:
        _check_transcript(parsed)
    if "text" in parsed and "audio" in parsed:
        raise HttpError(
            INVALID_MESSAGE, "audio: goes with phonemes; with text the speech is espeak-ng's"
        )
    if "text" not in parsed:
        given = [key for key in TEXT_FIELDS if key in parsed]
        if given:
            raise HttpError(INVALID_MESSAGE, f"{given[0]}: goes with text, not with {inputs[0]}")
    return parsed


def _check_transcript(body: dict[str, Any]) -> None:
    if not isinstance(body["transcript"], str):
        raise HttpError(INVALID_MESSAGE, "transcript: must be a string, what the audio says")
    if "audio" not in body:
        raise HttpError(INVALID_MESSAGE, "transcript: needs audio, the speech it transcribes")
    if "phoneme_source" in body:
        raise HttpError(
            INVALID_MESSAGE, "phoneme_source: goes with items; the aligner names its own phonemes"
        )


def _messages(body: dict[str, Any], encoding: Encoding) -> list[BodyPart]:
    """The body as protocol messages, each validated by the codec."""
    start = {key: body[key] for key in START_FIELDS if key in body}
    parts: list[tuple[str, dict[str, Any]]] = [("start", start)]
    audio = body.get("audio")
    if audio is not None:
        if not isinstance(audio, dict):
            raise HttpError(INVALID_MESSAGE, "audio: must be an object {sample_rate, pcm16}")
        parts.append(("audio", audio))
    if "words" in body:
        words = body["words"]
        if not isinstance(words, dict):
            raise HttpError(INVALID_MESSAGE, "words: must be an object {timings, format, ...}")
        parts.append(("words", words))
    elif "text" in body:
        parts.append(("text", {key: body[key] for key in TEXT_FIELDS if key in body}))
    elif "items" in body:
        parts.append(("phonemes", {"items": body["items"]}))
    decoded: list[BodyPart] = [_decoded(kind, fields, encoding) for kind, fields in parts]
    if "transcript" in body:
        decoded.append(Transcript(body["transcript"]))
    return [*decoded, End(REQUEST_ID)]


def _decoded(kind: str, fields: dict[str, Any], encoding: Encoding) -> Message:
    """One message of the body, validated as parsed: no number is re-encoded, so an
    out-of-range one (``1e999`` parses as infinity) gets the codec's error, not a fault."""
    payload = {"v": 1, "type": kind, "id": REQUEST_ID, **fields}
    decoded = payload_message(payload, encoding, sender="client")
    if isinstance(decoded, ProtocolError):
        prefix = f"{kind}." if kind in ("audio", "words") else ""
        located = f"{prefix}{decoded.where}: " if decoded.where else ""
        raise HttpError(decoded.code, f"{located}{decoded.message}")
    return decoded


def _aligned(transcript: Transcript, messages: list[BodyPart]) -> Alignment:
    """The body's audio aligned to its transcript; the aligner's refusals as ``HttpError``s
    located at ``audio`` (or ``transcript`` when it has no words)."""
    chunk = next(message for message in messages if isinstance(message, AudioChunk))
    samples = np.frombuffer(chunk.pcm16, "<i2").astype(np.float32) / 32768.0
    from ..frontends.align import align  # pocketsphinx loads with the first transcript

    where = "transcript" if not transcript.text.strip() else "audio"
    try:
        return align(Audio(samples, chunk.sample_rate), transcript.text, where=where)
    except LipstreamError as error:
        raise HttpError(error.code, f"{error.where}: {error.message}") from None


def _phonemes(alignment: Alignment) -> Phonemes:
    items = tuple(PhonemeItem(span.phoneme, span.start, span.end) for span in alignment.phones)
    return Phonemes(REQUEST_ID, items)


def _run(messages: list[BodyPart], state: ServerState) -> Synthesis:
    """Play the messages through a one-request session (in the thread pool); a transcript
    is aligned once the session has taken the start and the audio."""
    session = Session(
        state.catalog,
        replace(state.session_limits, max_requests=1),
        input_ledger=state.input_ledger,
    )
    ready: Ready | None = None
    done: Done | None = None
    blocks: list[np.ndarray] = []
    speech: list[AudioChunk] = []
    confidence: float | None = None
    try:
        for given in messages:
            message: Message
            if isinstance(given, Transcript):
                alignment = _aligned(given, messages)
                message, confidence = _phonemes(alignment), alignment.confidence
            else:
                message = given
            for outgoing in session.handle(message, time.monotonic()):
                answer = outgoing.message
                if isinstance(answer, ErrorMessage):
                    raise HttpError(answer.code, answer.message, details=answer.details)
                if isinstance(answer, Ready):
                    ready = answer
                elif isinstance(answer, Frames):
                    blocks.append(np.frombuffer(answer.data, "<f4").reshape(-1, answer.n_channels))
                elif isinstance(answer, Done):
                    done = answer
                elif isinstance(answer, AudioChunk):
                    speech.append(answer)
    finally:
        session.close()  # releases what the request held of its input
    if ready is None or done is None:
        raise HttpError(INTERNAL_ERROR, "the synthesis did not complete")
    width = len(ready.channels)
    frames = np.concatenate(blocks) if blocks else np.zeros((0, width), dtype="<f4")
    return Synthesis(ready, frames, done, speech, confidence)


class HeldAnswer(StreamingResponse):
    """A streamed answer that runs ``on_end`` once, however its sending ends (the last
    piece handed to the connection, or the client gone)."""

    def __init__(self, pieces: AsyncIterator[bytes], media_type: str, on_end: Callable[[], None]):
        super().__init__(pieces, media_type=media_type)
        self.on_end = on_end

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        try:
            await super().__call__(scope, receive, send)
        finally:
            self.on_end()


def _held_answer(
    pieces: AsyncIterator[bytes], held: int, encoding: ResponseFormat, state: ServerState
) -> HeldAnswer:
    """``pieces`` as a streamed answer whose ``held`` bytes count in ``state.answer_bytes``
    until it ends."""
    state.answer_bytes += held
    state.metrics.answer_bytes.set(state.answer_bytes)

    def release() -> None:
        state.answer_bytes -= held
        state.metrics.answer_bytes.set(state.answer_bytes)

    media_type = CSV_TYPE if encoding == "csv" else RESPONSE_TYPES[encoding]
    return HeldAnswer(pieces, media_type, release)


async def _slices(whole: bytes) -> AsyncIterator[bytes]:
    """An encoded answer ``SLICE_BYTES`` at a time, each once the previous one is in the
    connection's buffer."""
    view = memoryview(whole)
    for start in range(0, len(whole), SLICE_BYTES):
        yield bytes(view[start : start + SLICE_BYTES])


async def _json_pieces(result: Synthesis, state: ServerState) -> AsyncIterator[bytes]:
    """The bytes of ``json.dumps(answer)``: the fields up to ``"data":[``, the rows
    ``JSON_CHUNK_VALUES`` numbers at a time (each encoded in the pool), then ``]}``."""
    loop = asyncio.get_running_loop()
    frames = result.frames
    head = json.dumps(
        {**_fields(result, "json"), "data": []}, allow_nan=False, separators=JSON_SEPARATORS
    )
    yield head[: -len("]}")].encode()
    rows = max(1, JSON_CHUNK_VALUES // max(1, frames.shape[1]))
    for start in range(0, len(frames), rows):
        piece = await loop.run_in_executor(state.executor, _json_rows, frames[start : start + rows])
        yield piece if start == 0 else b"," + piece
    yield b"]}"


def _json_rows(frames: np.ndarray) -> bytes:
    """``frames`` as JSON rows of shortest float32 decimals, without the enclosing list's
    brackets."""
    return json_rows(frames).encode()


def _speech(result: Synthesis, encoding: Encoding) -> dict[str, Any] | None:
    """A text request's speech, whole: ``{sample_rate, pcm16}`` (base64 in JSON)."""
    if not result.speech:
        return None
    pcm = b"".join(chunk.pcm16 for chunk in result.speech)
    return {
        "sample_rate": result.speech[0].sample_rate,
        "pcm16": pcm if encoding == "msgpack" else base64.b64encode(pcm).decode("ascii"),
    }


def _fields(result: Synthesis, encoding: Encoding) -> dict[str, Any]:
    """The answer's fields before ``data``: ``ready``'s parameters, ``done``'s stats and a
    text request's ``speech``."""
    ready, frames = result.ready, result.frames
    body: dict[str, Any] = {
        "engine": ready.engine,
        "character": ready.character,
        "fps": ready.fps,
        "channels": list(ready.channels),
        "fidelity": ready.fidelity,
        "lookahead_ms": ready.lookahead_ms,
        "emotion": ready.emotion,
        "latency_budget_ms": ready.latency_budget_ms,
        "options": dict(ready.options),
        "phoneme_source": ready.phoneme_source,
        "first_frame": 0,
        "n_frames": len(frames),
        "n_channels": len(ready.channels),
        "stats": {"frames": result.done.stats.frames, "engine": dict(result.done.stats.engine)},
        "speech": _speech(result, encoding),
        "alignment": None if result.confidence is None else {"confidence": result.confidence},
    }
    return {key: value for key, value in body.items() if value is not None}


def error_response(error: HttpError, encoding: Encoding) -> Response:
    content: dict[str, Any] = {"code": error.code, "message": error.message}
    if error.details:
        content["details"] = error.details
    headers = {"WWW-Authenticate": "Bearer"} if error.status == 401 else None
    retry_after_ms = error.details.get("retry_after_ms")
    if isinstance(retry_after_ms, int):
        headers = {"Retry-After": str(math.ceil(retry_after_ms / 1000))}
    if encoding == "msgpack":
        return Response(
            msgpack.packb({"error": content}, use_bin_type=True),
            error.status,
            headers=headers,
            media_type=RESPONSE_TYPES[encoding],
        )
    return Response(
        json.dumps({"error": content}),
        error.status,
        headers=headers,
        media_type=RESPONSE_TYPES[encoding],
    )
