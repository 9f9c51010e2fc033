"""Retry delays: the server's own when it gives one, else exponential backoff with jitter."""

from __future__ import annotations

import random

from lipstream_client import HandshakeRejected, LipstreamServerError, ServerBusy, retry_delay_s
from lipstream_client.rest import HttpError


def test_the_servers_retry_after_wins_over_backoff() -> None:
    error = LipstreamServerError("server_busy", "busy", True, None, {"retry_after_ms": 1500})
    assert error.retry_after_s == 1.5
    closed = ServerBusy(1013, "server_busy", error)
    assert closed.retry_after_s == 1.5
    assert retry_delay_s(closed, attempt=9) == 1.5
    rejected = HandshakeRejected(503, "full", retry_after="2")
    assert rejected.retry_after_s == 2.0 and rejected.retryable
    http = HttpError("GET", "http://x/v1/engines", 503, b"", retry_after="3")
    assert retry_delay_s(http, attempt=0) == 3.0


def test_without_retry_after_the_delay_is_jittered_exponential_backoff() -> None:
    plain = ServerBusy(1013, "server_busy")
    assert plain.retry_after_s is None
    for bad in ("soon", "Wed, 21 Oct 2015 07:28:00 GMT", "-1"):
        assert HandshakeRejected(503, retry_after=bad).retry_after_s is None
    odd = LipstreamServerError("server_busy", "busy", True, None, {"retry_after_ms": "1500"})
    assert odd.retry_after_s is None
    rng = random.Random(3)
    for attempt, ceiling in ((0, 0.5), (1, 1.0), (3, 4.0), (10, 30.0)):
        delays = [retry_delay_s(plain, attempt, rng=rng) for _ in range(200)]
        assert all(0.0 <= delay <= ceiling for delay in delays)
        assert max(delays) > ceiling / 2  # spread over the range, not stuck at its bottom


def test_a_refused_upgrade_carries_the_error_of_its_json_body() -> None:
    body = (
        '{"error":{"code":"server_busy","message":"busy; retry in 1420 ms",'
        '"details":{"retry_after_ms":1420,"reason":"loop_busy"}}}'
    )
    rejected = HandshakeRejected(503, body, retry_after="2")
    assert rejected.error is not None
    assert (rejected.error.code, rejected.error.message) == (
        "server_busy",
        "busy; retry in 1420 ms",
    )
    assert rejected.error.details == {"retry_after_ms": 1420, "reason": "loop_busy"}
    assert rejected.retry_after_s == 1.42  # the body's milliseconds, finer than the header
    for other in ("full", "", body[:60], '{"error": "x"}', "[1]", '{"error":{"code":1}}'):
        refused = HandshakeRejected(503, other, retry_after="2")
        assert refused.error is None and refused.retry_after_s == 2.0
