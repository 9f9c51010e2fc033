"""Who may connect, and how fast they may talk: pure checks on headers and times.

Sketch: ``bearer_token`` reads the token from ``Authorization: Bearer`` or,
for browsers, which cannot set headers on a WebSocket, from the
``access_token`` query parameter (RFC 6750 sections 2.1 and 2.3);
``token_accepted`` compares it with every configured token in constant time.
``origin_allowed`` checks the ``Origin`` header against an allow-list of
exact origins (``scheme://host[:port]``, case-insensitive); a handshake
without ``Origin`` is allowed, because only browsers send one and the list
exists to stop other sites' pages from using the server through a visitor's
browser. ``TokenBucket`` limits messages per connection: ``rate`` tokens per
second refill a bucket of ``burst``, and each message takes one.
"""

from __future__ import annotations

import hmac
from collections.abc import Iterable, Sequence
from urllib.parse import parse_qs

_BEARER = "bearer "


def bearer_token(authorization: str | None, query_string: bytes) -> str | None:
    """The token from the Authorization header, else from ``?access_token=``; None if absent."""
    if authorization is not None and authorization[: len(_BEARER)].lower() == _BEARER:
        return authorization[len(_BEARER) :].strip() or None
    values = parse_qs(query_string.decode("latin-1")).get("access_token")
    return values[0] if values else None


def token_accepted(token: str | None, accepted: Sequence[str]) -> bool:
    """True when no tokens are configured, or ``token`` equals one of them."""
    if not accepted:
        return True
    if token is None:
        return False
    given = token.encode("utf-8", "surrogateescape")
    matches = [hmac.compare_digest(given, known.encode("utf-8")) for known in accepted]
    return any(matches)


def origin_allowed(origin: str | None, allowed: Iterable[str]) -> bool:
    """True with an empty allow-list, without an Origin header, or for a listed origin."""
    allowed = [entry.rstrip("/").lower() for entry in allowed]
    if not allowed or origin is None:
        return True
    return origin.rstrip("/").lower() in allowed


class TokenBucket:
    """A message-rate limit: ``rate`` per second sustained, ``burst`` at once."""

    def __init__(self, rate: float, burst: int, now: float) -> None:
        self.rate = rate
        self.burst = float(burst)
        self.tokens = float(burst)
        self.updated = now

    def take(self, now: float) -> bool:
        """Spend one token at monotonic time ``now``; False if the bucket is empty."""
        elapsed = max(0.0, now - self.updated)
        self.tokens = min(self.burst, self.tokens + elapsed * self.rate)
        self.updated = now
        if self.tokens < 1.0:
            return False
        self.tokens -= 1.0
        return True
