"""Hostile clients for the soak: each kind misbehaves in one way, again and again, until a deadline.

Sketch: a kind is one coroutine that makes one attempt (``ATTACKS``);
``run_kind`` repeats it until the soak's deadline and tallies what the server
answered: the protocol error codes it sent, how it closed the connection,
and what failed on the client's side. The kinds:

- ``silent_tcp``: a TCP connection that never sends a byte.
- ``partial_headers``: an HTTP request whose headers never end (one more
  header line every second, as slowloris does).
- ``pq_search``: an anime-graph request with ``options: {"search": "pq"}``
  and ``pq_phonemes`` phonemes sent at once: PQ-Matching's cost grows fast
  with the input (skipped when no character has an anime-graph model).
- ``json_flood``: a JSON request at ``flood_fps`` over ``flood_seconds`` of
  speech, read to the end.
- ``many_requests``: one connection opening more requests than the
  per-session limit, each left open for a while.
- ``stops_reading``: a request for many frames whose client never reads
  (its receive queue holds one message), held until the server lets go.
- ``malformed``: undecodable, unknown and incomplete messages.
- ``big_heads``: a WebSocket upgrade with one header line of ``BIG_HEADER_BYTES``.
- ``audio_flood``: one connection starting ``AUDIO_REQUESTS`` requests (on
  anime-graph when a character has it: it keeps a request's audio), then
  sending each ``AUDIO_SECONDS`` of 192 kHz audio, then their ends.
- ``pq_connections``: ``PQ_CONNECTIONS`` connections at once, each with one
  PQ request (``pq_window`` 6, ``PQ_PHONEMES`` phonemes), read to the end
  (skipped without an anime-graph model).
- ``rest_json_flood``: ``POST /v1/synthesize`` in JSON at ``flood_fps`` over
  ``flood_seconds`` of speech, its answer's head read and the rest left
  unread for ``UNREAD_HOLD_S``.
- ``client_flood``: ``CLIENT_FLOOD_SOCKETS`` WebSocket upgrades opened at once
  from a second loopback address (``FLOOD_ADDRESS``, so the per-client limits
  meet the flood and not the valid sessions, which come from 127.0.0.1), held
  for ``CLIENT_FLOOD_HOLD_S`` (skipped unless the target is 127.0.0.1).

The soak only measures: nothing here checks what the server should do.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import random
import time
from collections import Counter
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import Any
from urllib.parse import urlsplit

from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed as WebSocketClosed
from websockets.exceptions import InvalidHandshake
from websockets.typing import Subprotocol

from lipstream_client.client import ABNORMAL_CLOSURE, AsyncClient
from lipstream_client.codec import encode, subprotocol_for
from lipstream_client.exceptions import (
    ConnectionClosed,
    HandshakeRejected,
    LipstreamClientError,
    LipstreamServerError,
)
from lipstream_client.messages import (
    ClientMessage,
    Encoding,
    End,
    JsonValue,
    PhonemeItem,
    Phonemes,
    Start,
)

from .clips import Span, synthetic_clip

HOSTILE_KINDS: tuple[str, ...] = (
    "silent_tcp",
    "partial_headers",
    "pq_search",
    "json_flood",
    "many_requests",
    "stops_reading",
    "malformed",
    "big_heads",
    "audio_flood",
    "pq_connections",
    "rest_json_flood",
    "client_flood",
)
SLOW_HEADER_S = 1.0
BIG_HEADER_BYTES = 64 * 1024
AUDIO_REQUESTS = 4
AUDIO_SECONDS = 60
AUDIO_RATE = 192_000
PQ_CONNECTIONS = 5
PQ_WINDOW = 6
PQ_PHONEMES = 42
UNREAD_HOLD_S = 10.0
HEAD_BYTES = 64 * 1024
CLIENT_FLOOD_SOCKETS = 1500  # far above the default per-client cap (256)
CLIENT_FLOOD_HOLD_S = 2.0
LOOPBACK = "127.0.0.1"
FLOOD_ADDRESS = "127.0.0.2"
UPGRADE_KEY = "dGhlIHNhbXBsZSBub25jZQ=="
HOLD_REQUESTS_S = 2.0
MANY_REQUESTS = 80  # above the default per-session limit (64)
STOPS_READING_S = 60.0  # of speech at the flood's fps: megabytes of frames
REPLY_TIMEOUT_S = 5.0
HOSTILE_NICENESS = 10  # the measuring clients first, when they share a core with the attack
RETRY_PAUSE_S = 0.05
MALFORMED: tuple[str | bytes, ...] = (
    "not json",
    b"\x00\xff binary under the JSON subprotocol",
    "[1, 2, 3]",
    '{"type": "bogus", "id": "x"}',
    '{"type": "start", "id": "x"}',
    '{"type": "phonemes", "id": "nobody", "items": [["AA", 0.0, 0.1]]}',
    '{"type": "start", "id": "y", "engine": "none", "character": "none"}',
)


@dataclass(frozen=True)
class Target:
    """Where and what the hostile clients send."""

    url: str
    host: str
    port: int
    engine: str
    character: str
    encoding: Encoding
    token: str | None
    pq_character: str | None
    audio_character: str | None  # one with an hmm model, which audio alone drives
    pq_phonemes: int
    flood_seconds: float
    flood_fps: float
    seed: int


@dataclass
class KindTally:
    """What one kind's attempts met: server error codes, closes, client-side failures."""

    attempts: int = 0
    error_codes: Counter[str] = field(default_factory=Counter)
    closes: Counter[str] = field(default_factory=Counter)
    failures: Counter[str] = field(default_factory=Counter)
    skipped: str | None = None

    def server_error(self, error: LipstreamServerError) -> None:
        self.error_codes[error.code] += 1

    def closed(self, error: ConnectionClosed) -> None:
        if error.error is not None:
            self.server_error(error.error)
        self.closes["none" if error.code is None else str(error.code)] += 1

    def as_dict(self) -> dict[str, Any]:
        return {
            "attempts": self.attempts,
            "error_codes": dict(self.error_codes),
            "closes": dict(self.closes),
            "client_failures": dict(self.failures),
            "skipped": self.skipped,
        }


Attack = Callable[[Target, KindTally], Awaitable[None]]


async def run_kind(kind: str, target: Target, tally: KindTally, deadline: float) -> None:
    """Repeat ``kind``'s attack until ``deadline`` (``time.perf_counter``); an attempt
    still under way then is cut off and not counted as a failure."""
    attack = ATTACKS[kind]
    while (remaining := deadline - time.perf_counter()) > 0:
        tally.attempts += 1
        try:
            async with asyncio.timeout(remaining):
                await attack(target, tally)
        except TimeoutError:
            if time.perf_counter() >= deadline:
                return
            tally.failures["timeout"] += 1
        except ConnectionClosed as error:
            tally.closed(error)
        except LipstreamServerError as error:
            tally.server_error(error)
        except HandshakeRejected as error:
            if error.error is not None:
                tally.server_error(error.error)
            else:
                tally.failures[f"http_{error.status}"] += 1
        except (OSError, LipstreamClientError, WebSocketClosed, InvalidHandshake) as error:
            tally.failures[type(error).__name__] += 1
        if tally.skipped is not None:
            await asyncio.sleep(max(0.0, deadline - time.perf_counter()))
            return
        await asyncio.sleep(RETRY_PAUSE_S)


async def _until_closed(reader: asyncio.StreamReader, tally: KindTally) -> None:
    try:
        data = await reader.read(4096)
    except ConnectionResetError:
        tally.closes["reset"] += 1
        return
    tally.closes[_http_status(data) if data else "eof"] += 1


def _http_status(data: bytes) -> str:
    parts = data.split(b" ", 2)
    return f"http_{parts[1].decode('ascii', 'replace')}" if len(parts) > 1 else "data"


async def silent_tcp(target: Target, tally: KindTally) -> None:
    reader, writer = await asyncio.open_connection(target.host, target.port)
    try:
        await _until_closed(reader, tally)
    finally:
        writer.close()


async def partial_headers(target: Target, tally: KindTally) -> None:
    reader, writer = await asyncio.open_connection(target.host, target.port)
    try:
        writer.write(f"GET /healthz HTTP/1.1\r\nHost: {target.host}\r\n".encode())
        for line in range(1_000_000):
            writer.write(f"X-Slow-{line}: 1\r\n".encode())
            await writer.drain()
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(_until_closed(reader, tally), SLOW_HEADER_S)
                return
    finally:
        writer.close()


def _client(target: Target, encoding: Encoding | None = None) -> AsyncClient:
    return AsyncClient(target.url, encoding or target.encoding, target.token)


async def pq_search(target: Target, tally: KindTally) -> None:
    if target.pq_character is None:
        tally.skipped = "no character has an anime-graph model"
        return
    spans = _spans(target.pq_phonemes, target.seed)
    async with _client(target) as client:
        stream = await client.start("anime-graph", target.pq_character, options={"search": "pq"})
        await stream.send_phonemes(spans)
        await stream.end()
        async for _ in stream.frames():
            pass


def _spans(phonemes: int, seed: int) -> list[Span]:
    """``phonemes`` speech-like spans (clips average about 11 phonemes a second)."""
    seconds = 0.2
    spans = synthetic_clip(seconds, seed)
    while len(spans) < phonemes:
        seconds = min(2.0 * seconds + phonemes / 10.0, 600.0)
        spans = synthetic_clip(seconds, seed)
    return spans[:phonemes]


async def json_flood(target: Target, tally: KindTally) -> None:
    async with _client(target, "json") as client:
        stream = await client.start(target.engine, target.character, fps=target.flood_fps)
        await stream.send_phonemes(synthetic_clip(target.flood_seconds, target.seed))
        await stream.end()
        async for _ in stream.frames():
            pass


async def many_requests(target: Target, tally: KindTally) -> None:
    async with _client(target) as client:
        streams = []
        for _ in range(MANY_REQUESTS):
            stream = await client.start(target.engine, target.character)
            await stream.send_phonemes([("AA", 0.0, 0.1)])
            streams.append(stream)
        await asyncio.sleep(HOLD_REQUESTS_S)
        for stream in streams:
            try:
                stream.poll()
            except LipstreamServerError as error:
                tally.server_error(error)


async def stops_reading(target: Target, tally: KindTally) -> None:
    spans = synthetic_clip(STOPS_READING_S, target.seed)
    request: list[ClientMessage] = [
        Start("r", target.engine, target.character, fps=target.flood_fps),
        Phonemes("r", tuple(PhonemeItem(*span) for span in spans)),
        End("r"),
    ]
    headers = {"Authorization": f"Bearer {target.token}"} if target.token else None
    async with connect(
        target.url,
        subprotocols=[Subprotocol(subprotocol_for("json"))],
        additional_headers=headers,
        max_queue=1,
        max_size=None,
        proxy=None,
    ) as connection:
        for message in request:
            await connection.send(encode(message, "json"))
        await connection.wait_closed()
        tally.closes[stopped_reader_close(connection.close_code)] += 1


def stopped_reader_close(code: int | None) -> str:
    """How a client that never reads was let go: a close code, or ``reset`` for the TCP
    reset the server sends once its close frame cannot be delivered either (docs/reference/
    server.md), which the client library reports as 1006, a close it never received."""
    return "reset" if code == ABNORMAL_CLOSURE else str(code)


async def malformed(target: Target, tally: KindTally) -> None:
    headers = {"Authorization": f"Bearer {target.token}"} if target.token else None
    async with connect(
        target.url,
        subprotocols=[Subprotocol(subprotocol_for("json"))],
        additional_headers=headers,
        proxy=None,
    ) as connection:
        try:
            for payload in MALFORMED:
                await connection.send(payload)
                reply = await asyncio.wait_for(connection.recv(), REPLY_TIMEOUT_S)
                code = _error_code(reply)
                tally.error_codes[code or "no_error_reply"] += 1
        except WebSocketClosed:
            tally.closes[str(connection.close_code)] += 1


def _error_code(reply: str | bytes) -> str | None:
    try:
        message = json.loads(reply)
    except ValueError:
        return None
    if isinstance(message, dict) and message.get("type") == "error":
        return str(message.get("code"))
    return None


def _upgrade_head(target: Target, extra: str = "") -> bytes:
    path = urlsplit(target.url).path or "/"
    auth = f"Authorization: Bearer {target.token}\r\n" if target.token else ""
    return (
        f"GET {path} HTTP/1.1\r\nHost: {target.host}:{target.port}\r\nUpgrade: websocket\r\n"
        f"Connection: Upgrade\r\nSec-WebSocket-Key: {UPGRADE_KEY}\r\n"
        f"Sec-WebSocket-Version: 13\r\nSec-WebSocket-Protocol: {subprotocol_for('json')}\r\n"
        f"{auth}{extra}\r\n"
    ).encode()


async def big_heads(target: Target, tally: KindTally) -> None:
    reader, writer = await asyncio.open_connection(target.host, target.port)
    try:
        writer.write(_upgrade_head(target, f"X-Big: {'a' * BIG_HEADER_BYTES}\r\n"))
        await writer.drain()
        await _until_closed(reader, tally)
    finally:
        writer.close()


async def audio_flood(target: Target, tally: KindTally) -> None:
    if target.audio_character is None:
        tally.skipped = "no character has an hmm model (the engine audio alone drives)"
        return
    engine, character = "hmm", target.audio_character
    second = random.Random(target.seed).randbytes(2 * AUDIO_RATE)
    async with _client(target) as client:
        streams = [await client.start(engine, character) for _ in range(AUDIO_REQUESTS)]
        for _ in range(AUDIO_SECONDS):
            for stream in streams:
                if not stream.is_over:
                    await stream.send_audio(second, AUDIO_RATE)
        for stream in streams:
            if not stream.is_over:
                await stream.end()
        for stream in streams:
            try:
                await stream.done()
            except LipstreamServerError as error:
                tally.server_error(error)


async def pq_connections(target: Target, tally: KindTally) -> None:
    if target.pq_character is None:
        tally.skipped = "no character has an anime-graph model"
        return
    spans = _spans(PQ_PHONEMES, target.seed)
    character = target.pq_character

    async def one() -> None:
        async with _client(target) as client:
            options: dict[str, JsonValue] = {"search": "pq", "pq_window": PQ_WINDOW}
            stream = await client.start("anime-graph", character, options=options)
            await stream.send_phonemes(spans)
            await stream.end()
            async for _ in stream.frames():
                pass

    results = await asyncio.gather(*(one() for _ in range(PQ_CONNECTIONS)), return_exceptions=True)
    for result in results:
        if isinstance(result, LipstreamServerError):
            tally.server_error(result)
        elif isinstance(result, ConnectionClosed):
            tally.closed(result)
        elif isinstance(result, BaseException):
            raise result


async def rest_json_flood(target: Target, tally: KindTally) -> None:
    items = [
        {"phoneme": phoneme, "start": start, "end": end}
        for phoneme, start, end in synthetic_clip(target.flood_seconds, target.seed)
    ]
    body = json.dumps(
        {
            "engine": target.engine,
            "character": target.character,
            "fps": target.flood_fps,
            "items": items,
        }
    ).encode()
    auth = f"Authorization: Bearer {target.token}\r\n" if target.token else ""
    reader, writer = await asyncio.open_connection(target.host, target.port)
    try:
        writer.write(
            f"POST /v1/synthesize HTTP/1.1\r\nHost: {target.host}:{target.port}\r\n"
            f"Content-Type: application/json\r\nAccept: application/json\r\n{auth}"
            f"Content-Length: {len(body)}\r\n\r\n".encode()
            + body
        )
        await writer.drain()
        head = await reader.read(HEAD_BYTES)
        tally.closes[_http_status(head) if head else "eof"] += 1
        code = _error_code_of_json(head.partition(b"\r\n\r\n")[2])
        if code is not None:
            tally.error_codes[code] += 1
        await asyncio.sleep(UNREAD_HOLD_S)
    finally:
        writer.close()


async def client_flood(target: Target, tally: KindTally) -> None:
    if target.host != LOOPBACK:
        tally.skipped = f"floods from {FLOOD_ADDRESS}, which reaches only a {LOOPBACK} target"
        return
    head = _upgrade_head(target)
    writers: list[asyncio.StreamWriter] = []

    async def one() -> None:
        reader, writer = await asyncio.open_connection(
            target.host, target.port, local_addr=(FLOOD_ADDRESS, 0)
        )
        writers.append(writer)
        writer.write(head)
        try:
            answer = await asyncio.wait_for(reader.read(HEAD_BYTES), REPLY_TIMEOUT_S)
        except TimeoutError:
            answer = b""
        tally.closes[_http_status(answer) if answer else "no_answer"] += 1
        code = _error_code_of_json(answer.partition(b"\r\n\r\n")[2])
        if code is not None:
            tally.error_codes[code] += 1

    try:
        opened = await asyncio.gather(
            *(one() for _ in range(CLIENT_FLOOD_SOCKETS)), return_exceptions=True
        )
        for result in opened:
            if isinstance(result, BaseException):
                tally.failures[type(result).__name__] += 1
        await asyncio.sleep(CLIENT_FLOOD_HOLD_S)
    finally:
        for writer in writers:
            writer.close()


def _error_code_of_json(body: bytes) -> str | None:
    try:
        document = json.loads(body)
    except ValueError:
        return None
    error = document.get("error") if isinstance(document, dict) else None
    return str(error.get("code")) if isinstance(error, dict) else None


ATTACKS: dict[str, Attack] = {
    "silent_tcp": silent_tcp,
    "partial_headers": partial_headers,
    "pq_search": pq_search,
    "json_flood": json_flood,
    "many_requests": many_requests,
    "stops_reading": stops_reading,
    "malformed": malformed,
    "big_heads": big_heads,
    "audio_flood": audio_flood,
    "pq_connections": pq_connections,
    "rest_json_flood": rest_json_flood,
    "client_flood": client_flood,
}
