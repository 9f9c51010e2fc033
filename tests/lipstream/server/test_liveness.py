"""The health port answers from a thread: 200 while the event loop ticks, 503 once it has
stalled, whether or not the loop can run."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import httpx

from lipstream.config import ServerSettings
from lipstream.server.liveness import LivenessServer
from tests.helpers import eventually, free_port
from tests.lipstream.server.harness import serving

ANSWER_BOUND_S = 5.0  # whether it answers at all, not how fast


def _answers(url: str) -> tuple[int, dict[str, object]]:
    reply = httpx.get(url, timeout=ANSWER_BOUND_S)
    return reply.status_code, reply.json()


def test_a_recent_tick_is_alive_a_stale_one_is_stalled_other_paths_are_not_found() -> None:
    ticks = {"last": time.monotonic()}
    server = LivenessServer("127.0.0.1", 0, lambda: ticks["last"], stall_s=30.0)
    server.start()
    try:
        base = f"http://127.0.0.1:{server.port}"
        assert _answers(f"{base}/healthz") == (200, {"status": "ok"})
        ticks["last"] = time.monotonic() - 100.0
        status, body = _answers(f"{base}/healthz")
        answered = time.monotonic()
        assert status == 503 and body["status"] == "stalled"
        assert isinstance(body["event_loop_stalled_s"], float)
        # read between the tick and the answer's arrival
        assert 100.0 <= body["event_loop_stalled_s"] <= answered - ticks["last"]
        assert _answers(f"{base}/v1/engines")[0] == 404
    finally:
        server.stop()


def test_the_health_port_answers_while_the_event_loop_is_blocked(lerp_dir: Path) -> None:
    port = free_port()
    settings = ServerSettings(health_port=port, liveness_stall_s=0.5)
    with serving(lerp_dir, settings) as served:
        health = f"http://127.0.0.1:{port}/healthz"
        eventually(lambda: _answers(health)[0] == 200, "alive")
        # Block the serving loop itself until the test lets it go: the serving port cannot
        # answer, the health port still does, and says the loop has stalled; when the loop
        # runs again, alive again.
        released = threading.Event()
        served.loop.call_soon_threadsafe(released.wait)
        try:
            eventually(lambda: _answers(health)[0] == 503, "stalled while the loop is blocked")
            try:
                httpx.get(f"{served.http}/healthz", timeout=0.2)
                blocked_port_answered = True
            except httpx.TimeoutException:
                blocked_port_answered = False
        finally:
            released.set()
        assert not blocked_port_answered
        eventually(lambda: _answers(health)[0] == 200, "alive after the block")


def test_a_health_port_in_use_is_a_coded_error(lerp_dir: Path) -> None:
    import socket

    from lipstream.errors import LipstreamError
    from lipstream.server.app import _liveness

    with socket.socket() as taken:
        taken.bind(("0.0.0.0", 0))
        taken.listen()
        port = taken.getsockname()[1]
        settings = ServerSettings(health_port=port)
        try:
            _liveness(settings, time.monotonic)
        except LipstreamError as error:
            assert error.code == "invalid_setting" and error.where == "LIPSTREAM_HEALTH_PORT"
        else:
            raise AssertionError("binding a port in use succeeded")
