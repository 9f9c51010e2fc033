"""The server's HTTP endpoints through the standard library (``urllib``), no extra dependency.

Sketch: ``RestClient`` derives the HTTP root from either an ``http(s)://``
root or the ``ws(s)://.../v1/stream`` URL a streaming client uses, sends the
bearer token if one is given, and returns parsed answers. ``synthesize``
posts a whole utterance to ``POST /v1/synthesize``: the body is a ``start``
message's fields plus ``items`` (and optionally ``audio``), built and
validated by the protocol codec and sent as msgpack or JSON; ``synthesize_text``
sends a text instead of ``items``, ``synthesize_transcript`` audio and its
transcript for the server to align. The answer carries ``ready``'s resolved
parameters, every frame and ``done``'s stats (and a transcript's alignment
confidence), the frames equal to what ``/v1/stream`` sends for the same
request. An error answer (``{"error": {code, message, details}}``) becomes a
``RestServerError``; any other non-2xx an ``HttpError``; transport failures
stay ``OSError``. Loopback addresses bypass any configured proxy.
"""

from __future__ import annotations

import base64
import json
import urllib.error
import urllib.request
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any
from urllib.parse import urlsplit, urlunsplit

import msgpack

from .codec import encode
from .errors import INVALID_MESSAGE, EncodeError, ProtocolError
from .exceptions import LipstreamClientError, LipstreamServerError, retry_after_header_s
from .float32 import pack_float32
from .items import PhonemeLike, is_loopback_url, phoneme_items
from .messages import (
    DEFAULT_FPS,
    AudioChunk,
    DoneStats,
    Encoding,
    Frames,
    JsonMap,
    Message,
    OutputProfile,
    Phonemes,
    Ready,
    Start,
    Text,
)
from .wire import message_to_wire

DEFAULT_TIMEOUT_S = 10.0
_BODY_CHARS = 300
_HTTP_SCHEMES = {"ws": "http", "wss": "https", "http": "http", "https": "https"}
_MEDIA_TYPES: dict[Encoding, str] = {"msgpack": "application/msgpack", "json": "application/json"}
SYNTHESIZE_ID = "synthesize"
_ENVELOPE = ("v", "type", "id")


class HttpError(LipstreamClientError):
    """An HTTP endpoint answered ``status`` (not 2xx); ``raw`` is the body, ``body`` its
    first characters as text."""

    def __init__(
        self, method: str, url: str, status: int, raw: bytes, retry_after: str | None = None
    ) -> None:
        self.status = status
        self.raw = raw
        self.retry_after = retry_after
        self.body = raw.decode("utf-8", "replace")[:_BODY_CHARS].strip()
        super().__init__(f"{method} {url} answered HTTP {status}: {self.body}")

    @property
    def retryable(self) -> bool:
        return self.status in (429, 502, 503, 504)

    @property
    def retry_after_s(self) -> float | None:
        return retry_after_header_s(self.retry_after)


class RestServerError(LipstreamServerError):
    """``POST /v1/synthesize`` answered an error with a protocol ``code``; ``status`` is
    the HTTP status. The request has ended (``fatal``) and concerns no stream id."""

    def __init__(
        self, status: int, code: str, message: str, details: Mapping[str, Any] | None = None
    ) -> None:
        super().__init__(code, message, True, None, details)
        self.status = status


@dataclass(frozen=True)
class Synthesis:
    """A whole utterance's answer: ``ready``'s resolved parameters, every frame from
    frame 0 in one ``Frames`` block, and ``done``'s stats."""

    ready: Ready
    frames: Frames
    stats: DoneStats
    speech: tuple[bytes, int] | None = None
    """A text request's speech: (PCM16 little-endian mono bytes, sample rate Hz)."""
    alignment_confidence: float | None = None
    """A transcript request's forced-alignment confidence, 0 to 1 (None for others)."""

    @property
    def channels(self) -> tuple[str, ...]:
        return self.ready.channels

    def rows(self) -> list[list[float]]:
        """The frames, shape (n_frames, n_channels); frame i at i / fps seconds."""
        return self.frames.rows()


def http_root(url: str) -> str:
    """``scheme://host:port`` of the server behind an http(s) or ws(s) URL."""
    parts = urlsplit(url)
    scheme = _HTTP_SCHEMES.get(parts.scheme)
    if scheme is None or not parts.netloc:
        raise ValueError(f"expected an http(s):// or ws(s):// URL, got {url!r}")
    return urlunsplit((scheme, parts.netloc, "", "", ""))


@dataclass(frozen=True)
class Character:
    """A character the server can drive, and the engines that have a model of it."""

    name: str
    engines: tuple[str, ...]


class RestClient:
    """Blocking calls to a lipstream server's HTTP API; ``timeout`` in seconds per call;
    ``encoding`` the format of ``POST /v1/synthesize`` bodies and answers."""

    def __init__(
        self,
        url: str,
        token: str | None = None,
        timeout: float = DEFAULT_TIMEOUT_S,
        encoding: Encoding = "msgpack",
    ) -> None:
        self.root = http_root(url)
        self.encoding: Encoding = encoding
        self._token = token
        self._timeout = timeout
        # A proxy can never reach this machine's own loopback interface.
        handlers = [urllib.request.ProxyHandler({})] if is_loopback_url(self.root) else []
        self._opener = urllib.request.build_opener(*handlers)

    def healthy(self) -> bool:
        """``GET /healthz`` answers 200."""
        return self._status("/healthz") == 200

    def ready(self) -> bool:
        """``GET /readyz`` answers 200: the models are loaded."""
        return self._status("/readyz") == 200

    def engines(self) -> list[dict[str, Any]]:
        """``GET /v1/engines``: one mapping per engine (``name`` and more)."""
        engines: list[dict[str, Any]] = self.get_json("/v1/engines")["engines"]
        return engines

    def characters(self) -> list[Character]:
        """``GET /v1/characters``."""
        listing = self.get_json("/v1/characters")["characters"]
        return [Character(str(item["name"]), tuple(map(str, item["engines"]))) for item in listing]

    def default_target(self) -> tuple[str, str]:
        """(engine, character): the first character listed, with its first engine."""
        for character in self.characters():
            if character.engines:
                return character.engines[0], character.name
        raise LipstreamClientError(f"the server at {self.root} lists no character with a model")

    def synthesize(
        self,
        engine: str,
        character: str,
        items: Iterable[PhonemeLike],
        *,
        fps: float = DEFAULT_FPS,
        channels: Sequence[str] | None = None,
        output: OutputProfile | None = None,
        emotion: str | None = None,
        latency_budget_ms: float | None = None,
        options: JsonMap | None = None,
        phoneme_source: str | None = None,
        audio: tuple[bytes, int] | None = None,
    ) -> Synthesis:
        """``POST /v1/synthesize``: the frames of a whole utterance.

        Arguments as for ``AsyncClient.start``, plus the phoneme ``items`` and
        optional ``audio`` as (PCM16 little-endian bytes, sample rate Hz), in the
        client's ``encoding``. EncodeError (before
        sending) for input the protocol refuses; RestServerError for the
        server's refusals.
        """
        start = _start(
            engine,
            character,
            fps,
            channels,
            output,
            emotion,
            latency_budget_ms,
            options,
            phoneme_source,
        )
        parts: list[Message] = [start, Phonemes(SYNTHESIZE_ID, phoneme_items(items))]
        if audio is not None:
            parts.append(AudioChunk(SYNTHESIZE_ID, audio[1], bytes(audio[0])))
        return self._post_synthesize(_synthesize_body(parts, self.encoding), self.encoding)

    def synthesize_text(
        self,
        engine: str,
        character: str,
        text: str,
        *,
        lang: str | None = None,
        voice: str | None = None,
        rate: int | None = None,
        fps: float = DEFAULT_FPS,
        channels: Sequence[str] | None = None,
        output: OutputProfile | None = None,
        emotion: str | None = None,
        latency_budget_ms: float | None = None,
        options: JsonMap | None = None,
    ) -> Synthesis:
        """``POST /v1/synthesize`` with ``text`` for the server to speak (espeak-ng language
        ``lang``, ``voice``, ``rate`` as for ``Stream.send_text``): the frames and the
        speech (``Synthesis.speech``). Errors as for ``synthesize``."""
        start = _start(
            engine, character, fps, channels, output, emotion, latency_budget_ms, options
        )
        parts: list[Message] = [start, Text(SYNTHESIZE_ID, text, voice, rate, lang)]
        return self._post_synthesize(_synthesize_body(parts, self.encoding), self.encoding)

    def synthesize_transcript(
        self,
        engine: str,
        character: str,
        audio: tuple[bytes, int],
        transcript: str,
        *,
        fps: float = DEFAULT_FPS,
        channels: Sequence[str] | None = None,
        output: OutputProfile | None = None,
        emotion: str | None = None,
        latency_budget_ms: float | None = None,
        options: JsonMap | None = None,
    ) -> Synthesis:
        """``POST /v1/synthesize`` with recorded ``audio`` (PCM16 little-endian mono bytes,
        sample rate Hz) and its ``transcript``: the server aligns the words to the audio and
        answers the frames, with the alignment's confidence
        (``Synthesis.alignment_confidence``). Errors as for ``synthesize``; the server's
        refusals include ``empty_transcript`` and ``transcript_mismatch`` (audio the
        aligner cannot follow)."""
        if not isinstance(transcript, str):
            reason = "must be a string, what the audio says"
            raise EncodeError(ProtocolError(INVALID_MESSAGE, reason, where="transcript"))
        start = _start(
            engine, character, fps, channels, output, emotion, latency_budget_ms, options
        )
        parts: list[Message] = [start, AudioChunk(SYNTHESIZE_ID, audio[1], bytes(audio[0]))]
        body = _synthesize_body(parts, self.encoding, {"transcript": transcript})
        return self._post_synthesize(body, self.encoding)

    def _post_synthesize(self, body: bytes, encoding: Encoding) -> Synthesis:
        media = _MEDIA_TYPES[encoding]
        request = urllib.request.Request(
            self.root + "/v1/synthesize",
            data=body,
            method="POST",
            headers=self._headers({"Content-Type": media, "Accept": media}),
        )
        try:
            with self._open(request) as answer:
                return _synthesis(_parse(answer.read(), encoding))
        except HttpError as error:
            raise _server_error(error, encoding) from None

    def get_json(self, path: str) -> Any:
        """``GET path`` and parse the JSON answer; HttpError unless 2xx."""
        request = urllib.request.Request(self.root + path, headers=self._headers())
        with self._open(request) as answer:
            return json.loads(answer.read().decode("utf-8"))

    def _status(self, path: str) -> int:
        try:
            with self._open(
                urllib.request.Request(self.root + path, headers=self._headers())
            ) as answer:
                status: int = answer.status
                return status
        except HttpError as error:
            return error.status

    def _headers(self, extra: dict[str, str] | None = None) -> dict[str, str]:
        headers = {"Accept": "application/json", **(extra or {})}
        if self._token:
            headers["Authorization"] = f"Bearer {self._token}"
        return headers

    def _open(self, request: urllib.request.Request) -> Any:
        try:
            return self._opener.open(request, timeout=self._timeout)
        except urllib.error.HTTPError as error:
            raise HttpError(
                request.get_method(),
                request.full_url,
                error.code,
                error.read(),
                error.headers.get("Retry-After"),
            ) from None


def _start(
    engine: str,
    character: str,
    fps: float,
    channels: Sequence[str] | None,
    output: OutputProfile | None,
    emotion: str | None,
    latency_budget_ms: float | None,
    options: JsonMap | None,
    phoneme_source: str | None = None,
) -> Start:
    """The ``start`` of a synthesis request (its id ``SYNTHESIZE_ID``)."""
    return Start(
        SYNTHESIZE_ID,
        engine,
        character,
        fps,
        tuple(channels) if channels is not None else None,
        output,
        emotion,
        latency_budget_ms,
        dict(options or {}),
        phoneme_source,
    )


def _synthesize_body(
    parts: list[Message], encoding: Encoding, extra: JsonMap | None = None
) -> bytes:
    """One map: the start's fields, ``items`` and ``audio`` or the text's fields, each
    validated by the codec, and the ``extra`` fields no message carries (``transcript``)."""
    body: dict[str, Any] = dict(extra or {})
    for message in parts:
        encode(message, encoding)  # EncodeError for what the protocol refuses
        fields = {
            key: value
            for key, value in message_to_wire(message, encoding).items()
            if key not in _ENVELOPE
        }
        if isinstance(message, Phonemes):
            body["items"] = fields["items"]
        elif isinstance(message, AudioChunk):
            body["audio"] = fields
        else:
            body.update(fields)
    if encoding == "msgpack":
        packed: bytes = msgpack.packb(body, use_bin_type=True)
        return packed
    return json.dumps(body, ensure_ascii=False, allow_nan=False).encode("utf-8")


def _parse(data: bytes, encoding: Encoding) -> Any:
    if encoding == "msgpack":
        return msgpack.unpackb(data, raw=False, strict_map_key=True, max_ext_len=0)
    return json.loads(data.decode("utf-8"))


def _synthesis(answer: Any) -> Synthesis:
    """The typed answer; LipstreamClientError if it lacks a field or has a wrong type."""
    try:
        fps = float(answer["fps"])
        width = int(answer["n_channels"])
        data = answer["data"]
        if not isinstance(data, bytes):
            data = pack_float32([float(value) for row in data for value in row])
        ready = Ready(
            SYNTHESIZE_ID,
            str(answer["engine"]),
            str(answer["character"]),
            fps,
            tuple(map(str, answer["channels"])),
            float(answer["lookahead_ms"]),
            str(answer["fidelity"]),
            answer.get("emotion"),
            answer.get("latency_budget_ms"),
            answer.get("options") or {},
            answer.get("phoneme_source"),
        )
        stats = answer["stats"]
        done = DoneStats(int(stats["frames"]), engine=stats.get("engine") or {})
        frames = Frames(SYNTHESIZE_ID, 0, int(answer.get("first_frame", 0)), fps, width, data)
        speech = _speech(answer.get("speech"))
        alignment = answer.get("alignment")
        confidence = None if alignment is None else float(alignment["confidence"])
    except (KeyError, TypeError, ValueError, OverflowError) as error:
        raise LipstreamClientError(f"unexpected /v1/synthesize answer: {error!r}") from None
    if len(data) != frames.n_frames * width * 4 or frames.n_frames != answer.get("n_frames"):
        raise LipstreamClientError(
            "the /v1/synthesize answer's data does not hold "
            f"{answer.get('n_frames')} rows of {width} float32"
        )
    return Synthesis(ready, frames, done, speech, confidence)


def _speech(field: Any) -> tuple[bytes, int] | None:
    if field is None:
        return None
    pcm = field["pcm16"]
    if not isinstance(pcm, bytes):
        pcm = base64.b64decode(pcm, validate=True)
    return pcm, int(field["sample_rate"])


def _server_error(error: HttpError, encoding: Encoding) -> LipstreamClientError:
    """A RestServerError when the answer body holds the server's error object (in the
    requested encoding, or JSON when the server refused before reading the request's)."""
    for candidate in (encoding, "json"):
        try:
            detail = _parse(error.raw, candidate)["error"]
            return RestServerError(
                error.status, str(detail["code"]), str(detail["message"]), detail.get("details")
            )
        except (KeyError, TypeError, ValueError, msgpack.UnpackException):
            continue
    return error
