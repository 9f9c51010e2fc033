"""Exceptions the clients raise, mapped from ``error`` messages and WebSocket close codes.

Sketch: an ``error`` message from the server becomes a ``LipstreamServerError``
carrying its stable ``code``; a closed connection becomes a
``ConnectionClosed`` whose subclass names the close code's meaning
(``ServerBusy`` for 1013, ``ServerGoingAway`` for 1001 and 1012), with
``retryable`` telling the caller whether a retry with backoff may succeed
(``errors.RETRYABLE_CLOSE_CODES``) and ``retry_after_s`` how long the server
asked it to wait first (``details.retry_after_ms`` of ``server_busy``, or an
HTTP ``Retry-After``), which ``retry_delay_s`` honours. A refused HTTP upgrade
is a ``HandshakeRejected``; a server message the codec rejects is a
``ProtocolViolation``; a client that could not resume its requests after a
lost connection raises ``ResumeFailed``.
"""

from __future__ import annotations

import json
import random
from collections.abc import Mapping

from .errors import ERROR_CODES, RETRYABLE_CLOSE_CODES, CloseCode, ProtocolError
from .messages import ErrorMessage, JsonValue

_RETRYABLE_HTTP_STATUSES = frozenset({429, 502, 503, 504})
DEFAULT_BACKOFF_S = 0.5
MAX_BACKOFF_S = 30.0


class LipstreamClientError(Exception):
    """Base of every exception the lipstream clients raise."""

    @property
    def retryable(self) -> bool:
        """Whether repeating the operation later, with backoff, may succeed."""
        return False

    @property
    def retry_after_s(self) -> float | None:
        """How long the server asked the client to wait before retrying, if it said."""
        return None


class LipstreamServerError(LipstreamClientError):
    """The server reported an ``error``: ``code`` (see ``errors.ERROR_CODES``), its
    ``message``, whether it is ``fatal`` for its scope, the request ``id`` (None for the
    connection) and machine-readable ``details`` (e.g. ``min_budget_ms``)."""

    def __init__(
        self,
        code: str,
        message: str,
        fatal: bool,
        id: str | None = None,
        details: Mapping[str, JsonValue] | None = None,
    ) -> None:
        self.code = code
        self.message = message
        self.fatal = fatal
        self.id = id
        self.details: Mapping[str, JsonValue] = details or {}
        scope = f"request {id!r}" if id is not None else "connection"
        super().__init__(f"{scope}: {message} [{code}]")

    @classmethod
    def from_message(cls, error: ErrorMessage) -> LipstreamServerError:
        return cls(error.code, error.message, error.fatal, error.id, error.details)

    @property
    def retryable(self) -> bool:
        info = ERROR_CODES.get(self.code)
        return info is not None and info.close_code in RETRYABLE_CLOSE_CODES

    @property
    def retry_after_s(self) -> float | None:
        value = self.details.get("retry_after_ms")
        if isinstance(value, (int, float)) and not isinstance(value, bool) and value >= 0:
            return value / 1000.0
        return None


class ConnectionClosed(LipstreamClientError):
    """The WebSocket closed with ``code`` and ``reason`` (the error code that caused it,
    if any); ``error`` is the connection-level ``error`` message the server sent first."""

    def __init__(
        self, code: int | None, reason: str = "", error: LipstreamServerError | None = None
    ) -> None:
        self.code = code
        self.reason = reason
        self.error = error
        shown = f"close code {code}" if code is not None else "no close frame"
        detail = f": {error.message}" if error is not None else (f" ({reason})" if reason else "")
        super().__init__(f"connection closed, {shown}{detail}")

    @property
    def retryable(self) -> bool:
        return self.code in RETRYABLE_CLOSE_CODES

    @property
    def retry_after_s(self) -> float | None:
        return self.error.retry_after_s if self.error is not None else None


class ServerBusy(ConnectionClosed):
    """Closed with 1013: the server is at its capacity. Retry after ``retry_after_s``, or
    with exponential backoff (``retry_delay_s`` does both)."""


class ServerGoingAway(ConnectionClosed):
    """Closed with 1001 (drained for shutdown) or 1012 (restarted): reconnect and retry."""


class ResumeFailed(ConnectionClosed):
    """The connection was lost (``lost``) and a client with a ``ResumePolicy`` could not
    resume its requests: ``attempts`` connection attempts in a row failed, the last with
    ``last``."""

    def __init__(self, lost: ConnectionClosed, last: LipstreamClientError, attempts: int) -> None:
        super().__init__(lost.code, lost.reason, lost.error)
        self.lost = lost
        self.last = last
        self.attempts = attempts
        self.args = (f"{lost}; {attempts} attempts to resume failed, the last: {last}",)


class HandshakeRejected(LipstreamClientError):
    """The server refused the WebSocket upgrade with HTTP ``status`` (403 when it speaks
    none of the offered subprotocols, 503 when it is busy or holds as many connections as it
    can); ``retry_after`` is its ``Retry-After`` header, if any, and ``error`` the lipstream
    error of a JSON body (``{"error": {"code", "message", "details"}}``, e.g. ``server_busy``
    with ``details.retry_after_ms``), if it sent one."""

    def __init__(self, status: int, body: str = "", retry_after: str | None = None) -> None:
        self.status = status
        self.body = body
        self.retry_after = retry_after
        self.error = error_of_body(body)
        super().__init__(
            f"WebSocket upgrade refused with HTTP {status}" + (f": {body}" if body else "")
        )

    @property
    def retryable(self) -> bool:
        return self.status in _RETRYABLE_HTTP_STATUSES

    @property
    def retry_after_s(self) -> float | None:
        if self.error is not None and self.error.retry_after_s is not None:
            return self.error.retry_after_s
        return retry_after_header_s(self.retry_after)


def error_of_body(body: str) -> LipstreamServerError | None:
    """The lipstream error an HTTP answer's JSON body carries, or None for any other body."""
    try:
        parsed = json.loads(body)
    except ValueError:
        return None
    error = parsed.get("error") if isinstance(parsed, dict) else None
    if not isinstance(error, dict):
        return None
    code, message = error.get("code"), error.get("message")
    details = error.get("details", {})
    if not (isinstance(code, str) and isinstance(message, str) and isinstance(details, dict)):
        return None
    return LipstreamServerError(code, message, True, None, details)


class ProtocolViolation(LipstreamClientError):
    """The server sent a message that the protocol codec rejects."""

    def __init__(self, error: ProtocolError) -> None:
        self.error = error
        super().__init__(f"invalid message from the server: {error}")


def closed_error(
    code: int | None, reason: str, error: LipstreamServerError | None = None
) -> ConnectionClosed:
    """The ``ConnectionClosed`` subclass that names the close code's meaning."""
    if code == CloseCode.TRY_AGAIN_LATER:
        return ServerBusy(code, reason, error)
    if code in (CloseCode.GOING_AWAY, CloseCode.SERVICE_RESTART):
        return ServerGoingAway(code, reason, error)
    return ConnectionClosed(code, reason, error)


def retry_after_header_s(value: str | None) -> float | None:
    """An HTTP ``Retry-After`` in seconds (the delay form; a date or garbage gives None)."""
    if value is None or not value.strip().isdigit():
        return None
    return float(value.strip())


def retry_delay_s(
    error: LipstreamClientError,
    attempt: int,
    base_s: float = DEFAULT_BACKOFF_S,
    cap_s: float = MAX_BACKOFF_S,
    rng: random.Random | None = None,
) -> float:
    """How long to wait before retry number ``attempt`` (0 for the first) after ``error``:
    the server's ``retry_after_s`` when it gave one, else exponential backoff with full
    jitter (uniform in [0, min(cap_s, base_s * 2**attempt)])."""
    asked = error.retry_after_s
    if asked is not None:
        return asked
    ceiling = min(cap_s, base_s * 2.0 ** max(0, attempt))
    return (rng or random).uniform(0.0, ceiling)
