"""Load-based admission: the sans-I/O policy with hand-computed load, the ``start`` refusal of
a session, and ``server_busy`` with ``retry_after_ms`` from a real server."""

from __future__ import annotations

import asyncio
import math
import random
import re
import socket
import threading
import time
from contextlib import ExitStack
from dataclasses import replace
from pathlib import Path
from urllib.parse import urlsplit

import httpx

from lipstream.config import ServerSettings
from lipstream.engines.base import Lookahead, Rung
from lipstream.server.budget import RungEstimate
from lipstream.server.catalog import Catalog
from lipstream.server.load import LoadSample
from lipstream.server.overload import (
    LAG_FROM_SESSIONS,
    LEARN_FROM_SESSIONS,
    MEMORY_RETRY_AFTER_MS,
    RATE_RETRY_AFTER_MS,
    RECENT_S,
    RETRY_AFTER_MS,
    UPGRADE_TTL_S,
    LoadLimits,
    OverloadPolicy,
    Refusal,
    Upgrade,
    calibrated_session_cost,
    engine_costs,
)
from lipstream.server.request import RequestLimits
from lipstream.server.session import Session, SessionLimits
from lipstream_client import (
    AsyncClient,
    ErrorMessage,
    HandshakeRejected,
    Ready,
    Start,
    retry_delay_s,
)
from tests.helpers import eventually
from tests.lipstream.server.harness import client, serving

# Binary fractions, so the hand-computed admission counts are exact.
LIMITS = LoadLimits(1000.0, 50.0, 0.75, session_cost=0.125, engine_costs={"viseme-lerp": 0.125})
QUIET = LoadSample(lag_ms=1.0, loop_busy=0.0, rss_mb=100.0)


def policy(limits: LoadLimits = LIMITS) -> OverloadPolicy:
    return OverloadPolicy(limits, random.Random(7))


def admitted_in_a_burst(overload: OverloadPolicy, load: LoadSample, now: float) -> int:
    for count in range(1000):
        if overload.session_refusal(load, 0, now, object()) is not None:
            return count
    raise AssertionError("the burst was never refused")


def test_a_burst_is_admitted_up_to_the_busy_limit_and_stays_counted_until_it_streams() -> None:
    overload = policy()
    keys = [f"s{index}" for index in range(6)]
    for key in keys:
        assert overload.session_refusal(QUIET, 0, 0.0, key) is None
    refusal = overload.session_refusal(QUIET, 0, 0.0, object())  # 7 x 0.125 > 0.75
    assert refusal is not None and refusal.reason == "loop_busy"
    # Half a window later none of the six has started a request: the window has measured
    # nothing of them, so they still fill the loop (counting them by their age, as a
    # measured part of them, admitted 3 more in a storm of connections that had not started).
    assert admitted_in_a_burst(overload, QUIET, now=RECENT_S / 2) == 0
    for key in keys:  # each first start fits: the pending one it was is no longer counted
        assert overload.start_refusal(QUIET, key, "viseme-lerp", RECENT_S / 2) is None
    # Another half window on, the window has measured half of each start:
    # 6 x 0.5 x 0.125 = 0.375 of the 0.75 is unmeasured, room for 3 more.
    assert admitted_in_a_burst(overload, QUIET, now=RECENT_S) == 3
    later = policy()
    for key in keys:
        later.session_refusal(QUIET, 0, 0.0, key)
        later.start_refusal(QUIET, key, "viseme-lerp", 0.0)
    assert admitted_in_a_burst(later, QUIET, now=RECENT_S) == 6  # all measured by now
    busy = LoadSample(lag_ms=1.0, loop_busy=0.5, rss_mb=100.0)
    assert admitted_in_a_burst(policy(), busy, now=0.0) == 2  # 0.5 + 2 x 0.125 = 0.75


def test_a_closed_pending_session_frees_its_share() -> None:
    overload = policy()
    for key in range(6):
        assert overload.session_refusal(QUIET, 0, 0.0, key) is None
    assert (
        overload.session_refusal(QUIET, 0, 5.0, object()) is not None
    )  # still pending, still counted
    overload.closed(0)
    overload.closed(1)
    assert admitted_in_a_burst(overload, QUIET, now=5.0) == 2


def test_each_engine_is_priced_at_its_own_cost_at_the_first_start() -> None:
    # One engine costs three cores (a model whose calibration went wrong): its starts are
    # refused, while sessions of the others are admitted and start (with one cost for all,
    # the dearest, every session was refused at the handshake).
    costs = {"viseme-lerp": 0.125, "expressive-dp": 2.988}
    overload = policy(LoadLimits(1000.0, 50.0, 0.75, session_cost=0.125, engine_costs=costs))
    assert overload.session_refusal(QUIET, 0, 0.0, "dear") is None
    dear = overload.start_refusal(QUIET, "dear", "expressive-dp", 0.0)
    assert dear is not None and dear.reason == "loop_busy" and "expressive-dp" in dear.message
    for key in ("a", "b", "c"):
        assert overload.session_refusal(QUIET, 0, 0.0, key) is None
        assert overload.start_refusal(QUIET, key, "viseme-lerp", 0.0) is None
    # A priced session's later starts are checked for memory only.
    assert overload.start_refusal(LoadSample(1.0, 0.74, 100.0), "a", "viseme-lerp", 9.0) is None
    full = overload.start_refusal(LoadSample(1.0, 0.0, 1000.5), "a", "viseme-lerp", 9.0)
    assert full is not None and full.reason == "memory"
    # A start of an engine not loaded prices nothing (it is refused as unknown_engine).
    assert overload.start_refusal(QUIET, "dear", "no-such-engine", 9.0) is None
    assert "dear" not in overload.priced
    # The refused session stays unpriced: a later start that fits is admitted.
    assert overload.start_refusal(QUIET, "dear", "viseme-lerp", 9.0) is None
    # With 0.5 of the loop busy, a session of 0.125 fits twice more, and not a third time.
    busy = LoadSample(1.0, 0.5, 100.0)
    assert [overload.start_refusal(busy, key, "viseme-lerp", 20.0) is None for key in "xyz"] == [
        True,
        True,
        False,
    ]


def test_engine_costs_are_each_engines_costliest_default_rung(catalog: Catalog) -> None:
    expected: dict[str, float] = {}
    for model in catalog.registry.models.values():
        per_phoneme_ms = catalog.ladder(model)[0].per_phoneme_ms
        cost = (per_phoneme_ms + 0.13) / 80.0  # ms per 80 ms of speech: share of a core
        engine = model.manifest.engine
        expected[engine] = max(expected.get(engine, 0.0), cost)
    costs = engine_costs(catalog)
    assert costs.keys() == expected.keys() and len(costs) >= 2
    assert all(math.isclose(costs[engine], expected[engine]) for engine in costs)


def test_lag_and_memory_refuse_at_their_limits() -> None:
    at_limits = LoadSample(lag_ms=50.0, loop_busy=0.0, rss_mb=1000.0)
    assert policy().session_refusal(at_limits, LAG_FROM_SESSIONS, 0.0, object()) is None
    lagging = policy().session_refusal(
        LoadSample(50.5, 0.0, 100.0), LAG_FROM_SESSIONS, 0.0, object()
    )
    assert lagging is not None and lagging.reason == "loop_lag"
    waiting = LoadSample(1.0, 0.0, 100.0, receive_lag_ms=50.5)
    queued = policy().session_refusal(waiting, LAG_FROM_SESSIONS, 0.0, object())
    assert queued is not None and queued.reason == "receive_lag"
    assert "50 ms" in queued.message
    # With fewer sessions open the lag is the machine's, not theirs: no refusal.
    few = policy().session_refusal(
        LoadSample(500.0, 0.0, 100.0), LAG_FROM_SESSIONS - 1, 0.0, object()
    )
    assert few is None
    full = LoadSample(lag_ms=1.0, loop_busy=0.0, rss_mb=1000.5)
    for refusal in (
        policy().session_refusal(full, 0, 0.0, object()),
        policy().request_refusal(full),
    ):
        assert refusal is not None and refusal.reason == "memory"
        assert refusal.code == "server_busy"
        assert MEMORY_RETRY_AFTER_MS <= refusal.retry_after_ms < 2 * MEMORY_RETRY_AFTER_MS
    assert policy().request_refusal(LoadSample(lag_ms=500.0, loop_busy=1.0, rss_mb=10.0)) is None


def test_retry_after_is_spread_over_one_more_base() -> None:
    overload = policy()
    lagging = LoadSample(lag_ms=99.0, loop_busy=0.0, rss_mb=1.0)
    waits = []
    for _ in range(40):
        refusal = overload.session_refusal(lagging, LAG_FROM_SESSIONS, 0.0, object())
        assert refusal is not None
        assert refusal.details == {"retry_after_ms": refusal.retry_after_ms, "reason": "loop_lag"}
        assert f"retry in {refusal.retry_after_ms} ms" in refusal.message
        waits.append(refusal.retry_after_ms)
    assert all(RETRY_AFTER_MS <= wait < 2 * RETRY_AFTER_MS for wait in waits)
    assert len(set(waits)) > 1


def test_the_session_cost_is_learned_from_the_streaming_sessions_only() -> None:
    overload = policy(LoadLimits(1000.0, 50.0, 0.75, session_cost=0.01))
    for key in range(LEARN_FROM_SESSIONS - 1):
        overload.set_streaming(key, True)
    overload.session_refusal(LoadSample(1.0, 0.6, 1.0), 100, 0.0, object())
    assert overload.session_cost == 0.01  # too few streaming to learn from: the calibrated
    overload.set_streaming(LEARN_FROM_SESSIONS - 1, True)
    # 16 streaming among 116 open (100 admitted, not started): 0.64 / 16, not 0.64 / 116.
    overload.session_refusal(LoadSample(1.0, 0.64, 1.0), 116, 10.0, object())
    assert math.isclose(overload.session_cost, 0.04)
    for key in range(LEARN_FROM_SESSIONS, 2 * LEARN_FROM_SESSIONS):
        overload.set_streaming(key, True)
    overload.session_refusal(LoadSample(1.0, 0.64, 1.0), 132, 20.0, object())
    assert math.isclose(overload.session_cost, 0.038)  # 0.04 + 0.1 x (0.02 - 0.04)
    for key in range(2 * LEARN_FROM_SESSIONS):
        overload.closed(key)
    assert not overload.streaming
    dear = policy(LoadLimits(1000.0, 50.0, 0.75, session_cost=0.125))
    for key in range(16):
        dear.set_streaming(key, True)
    dear.session_refusal(LoadSample(1.0, 0.32, 1.0), 16, 0.0, object())
    # measured below the calibrated estimate: the calibrated one stands
    assert math.isclose(dear.session_cost, 0.125)


def test_the_calibrated_cost_is_the_costliest_default_rung_plus_message_overhead() -> None:
    rung = Rung("full", Lookahead())
    ladders = [
        (RungEstimate(rung, 0.0, 1.0, 0.05), RungEstimate(rung, 0.0, 1.0, 9.0)),
        (RungEstimate(rung, 0.0, 1.0, 0.2),),
    ]
    # (0.2 ms + 0.13 ms per message) per 80 ms of speech, as a fraction of one core
    assert math.isclose(calibrated_session_cost(ladders), 0.33 / 80)


def test_a_refused_start_ends_only_that_request(catalog: Catalog) -> None:
    refusals: list[Refusal | None] = [Refusal("memory", "the server is full", 5000)]
    limits = SessionLimits(4, RequestLimits(1000, 100_000, 150.0))
    session = Session(catalog, limits, lambda engine: refusals[-1])
    [answer] = session.handle(Start("a", "viseme-lerp", "demo"), 0.0)
    assert answer.message == ErrorMessage(
        "server_busy",
        "the server is full",
        "a",
        True,
        {"retry_after_ms": 5000, "reason": "memory"},
    )
    assert session.active_requests == 0
    refusals.append(None)
    [ready] = session.handle(Start("a", "viseme-lerp", "demo"), 0.1)
    assert isinstance(ready.message, Ready) and session.active_requests == 1


def refused_upgrade(url: str) -> HandshakeRejected:
    async def connect() -> HandshakeRejected:
        try:
            async with AsyncClient(url, open_timeout=10):
                pass
        except HandshakeRejected as rejected:
            return rejected
        raise AssertionError("the upgrade was admitted")

    return asyncio.run(connect())


def test_an_overloaded_server_refuses_upgrades_with_http_503_and_server_busy(
    lerp_dir: Path,
) -> None:
    # Any measured busy time at all exceeds this limit, and a session's cost alone does.
    with serving(lerp_dir, ServerSettings(max_loop_busy=1e-9)) as served:
        rejected = refused_upgrade(served.ws)
        assert rejected.status == 503 and rejected.error is not None
        assert (rejected.error.code, rejected.error.details["reason"]) == (
            "server_busy",
            "loop_busy",
        )
        wait = rejected.error.details["retry_after_ms"]
        assert isinstance(wait, int) and RETRY_AFTER_MS <= wait < 2 * RETRY_AFTER_MS
        assert rejected.retry_after == str(math.ceil(wait / 1000))
        assert rejected.retry_after_s == wait / 1000
        assert retry_delay_s(rejected, attempt=5) == wait / 1000
        assert httpx.get(f"{served.http}/healthz").json() == {"status": "ok"}
        metrics = httpx.get(f"{served.http}/metrics").text
        assert 'lipstream_connections_refused_total{code="server_busy"} 1.0' in metrics
        assert 'lipstream_busy_refusals_total{reason="loop_busy"} 1.0' in metrics
        assert served.app.state.startup.server.overload.policy.pending == {}
        resident = re.search(r"^lipstream_resident_memory_bytes (\S+)$", metrics, re.M)
        assert resident is not None and float(resident.group(1)) > 1 << 20
        busy = re.search(r"^lipstream_event_loop_busy_ratio (\S+)$", metrics, re.M)
        assert busy is not None and 0.0 <= float(busy.group(1)) <= 1.0


def test_an_admitted_upgrade_is_pending_under_its_connection_until_it_closes(
    lerp_dir: Path,
) -> None:
    with serving(lerp_dir) as served:
        policy = served.app.state.startup.server.overload.policy
        with client(served.ws) as ws:
            [key] = policy.pending  # adopted by the endpoint: no Upgrade key left
            assert not isinstance(key, Upgrade)
            ws.send(Start("a", "viseme-lerp", "demo"))
            assert isinstance(ws.recv(), Ready)
            assert policy.pending == {} and len(policy.priced) == 1
        eventually(lambda: not policy.priced, "the closed session forgotten")


def test_above_the_memory_ceiling_nothing_new_is_taken_on(lerp_dir: Path) -> None:
    with serving(lerp_dir, ServerSettings(max_memory_mb=1)) as served:
        rejected = refused_upgrade(served.ws)
        assert rejected.status == 503 and rejected.error is not None
        assert rejected.error.details["reason"] == "memory"
        body = {"engine": "viseme-lerp", "character": "demo", "items": []}
        refused = httpx.post(f"{served.http}/v1/synthesize", json=body)
        assert refused.status_code == 503
        detail = refused.json()["error"]
        assert detail["code"] == "server_busy" and detail["details"]["reason"] == "memory"
        wait_ms = detail["details"]["retry_after_ms"]
        assert MEMORY_RETRY_AFTER_MS <= wait_ms < 2 * MEMORY_RETRY_AFTER_MS
        assert refused.headers["retry-after"] == str(math.ceil(wait_ms / 1000))


def test_upgrades_of_a_burst_count_against_each_other_at_once() -> None:
    """An upgrade admitted by the HTTP protocol is pending at once (the next head of the
    burst sees it), moves to its connection when the endpoint adopts it, and stops counting
    after UPGRADE_TTL_S when no endpoint ever does."""
    overload = policy()
    upgrades = [Upgrade(("127.0.0.1", 40000 + index)) for index in range(6)]
    for upgrade in upgrades:
        assert overload.session_refusal(QUIET, 0, 0.0, upgrade) is None
    refusal = overload.session_refusal(QUIET, 0, 0.0, Upgrade(("127.0.0.1", 1)))
    assert refusal is not None and refusal.reason == "loop_busy"  # 7 x 0.125 > 0.75
    assert overload.adopt(upgrades[0], "session") and not overload.adopt(upgrades[0], "again")
    assert not overload.adopt(Upgrade(("127.0.0.1", 1)), "refused one")
    overload.closed("session")  # the adopted one closes: its share is free
    assert admitted_in_a_burst(overload, QUIET, now=1.0) == 1
    # The five never adopted still count just before the TTL, and not from it on.
    assert admitted_in_a_burst(overload, QUIET, now=UPGRADE_TTL_S - 0.5) == 0
    fresh = policy()
    for upgrade in upgrades:
        fresh.session_refusal(QUIET, 0, 0.0, upgrade)
    assert admitted_in_a_burst(fresh, QUIET, now=UPGRADE_TTL_S) == 6
    assert not fresh.adopt(upgrades[2], "too late")


def test_only_the_upgrades_admitted_a_ttl_ago_stop_counting() -> None:
    """Upgrades admitted at different times expire each at its own TTL: two admitted at
    0 s stop counting at UPGRADE_TTL_S, the two admitted 5 s later still count then, and
    a re-admitted client counts from its later admission."""
    overload = policy()
    early = [Upgrade(("127.0.0.1", 41000 + index)) for index in range(2)]
    late = [Upgrade(("127.0.0.1", 42000 + index)) for index in range(2)]
    for upgrade in early:
        assert overload.session_refusal(QUIET, 0, 0.0, upgrade) is None
    for upgrade in late:
        assert overload.session_refusal(QUIET, 0, 5.0, upgrade) is None
    assert overload.session_refusal(QUIET, 0, 5.0, early[0]) is None  # re-admitted at 5 s
    # 0.75 / 0.125 = 6 sessions fit: three upgrades still count at the TTL, so three more.
    assert admitted_in_a_burst(overload, QUIET, now=UPGRADE_TTL_S) == 3
    assert not overload.adopt(early[1], "expired") and overload.adopt(early[0], "readmitted")
    assert overload.adopt(late[1], "late") and not overload.adopt(late[1], "twice")


def test_shedding_needs_a_far_lagging_loop_and_enough_sessions() -> None:
    overload = policy()  # max_lag_ms 50: shedding beyond 4 x 50 ms
    assert overload.shedding(LoadSample(200.5, 0.0, 1.0), LAG_FROM_SESSIONS)
    assert not overload.shedding(LoadSample(200.0, 0.0, 1.0), LAG_FROM_SESSIONS)
    assert not overload.shedding(LoadSample(9999.0, 0.0, 1.0), LAG_FROM_SESSIONS - 1)
    assert overload.shedding(LoadSample(1.0, 0.0, 1.0, receive_lag_ms=200.5), LAG_FROM_SESSIONS)


UPGRADE = (
    b"GET /v1/stream HTTP/1.1\r\nHost: test\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
    b"Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n"
    b"Sec-WebSocket-Protocol: lipstream.v1.msgpack\r\n\r\n"
)


def test_a_loop_held_far_behind_sheds_upgrades_with_http_503(lerp_dir: Path) -> None:
    """With 16 sessions open, an upgrade that arrives while the loop is held for 0.5 s (ten
    times the 10 ms lag limit, above the 4x of shedding) is answered 503 before any
    WebSocket work."""
    held = threading.Event()

    async def hold_the_loop() -> None:
        held.set()
        time.sleep(0.5)

    settings = ServerSettings(max_loop_lag_ms=10.0, max_session_rate=0.0)  # 17 at once
    with serving(lerp_dir, settings) as served, ExitStack() as stack:
        for _ in range(LAG_FROM_SESSIONS):
            ws = stack.enter_context(client(served.ws))
            ws.send(Start("a", "viseme-lerp", "demo"))
            assert isinstance(ws.recv(), Ready)
        parts = urlsplit(served.http)
        sock = stack.enter_context(socket.create_connection((parts.hostname, parts.port)))
        sock.settimeout(10.0)
        connections = served.server.server_state.connections
        eventually(  # accepted by the server before the hold
            lambda: len(connections) > LAG_FROM_SESSIONS, "the new connection accepted"
        )
        assert len(connections) == LAG_FROM_SESSIONS + 1
        served.call_soon(hold_the_loop())
        assert held.wait(10.0)
        sock.sendall(UPGRADE)
        answer = b""
        while chunk := sock.recv(65536):
            answer += chunk
        assert answer.startswith(b"HTTP/1.1 503 Service Unavailable\r\n")
        metrics = httpx.get(f"{served.http}/metrics").text
        assert 'lipstream_connections_refused_total{code="shedding"} 1.0' in metrics


def test_an_engine_priced_out_refuses_its_start_and_not_the_session(lerp_dir: Path) -> None:
    """On a real server: with viseme-lerp priced at three cores (as a model whose
    calibration went wrong once priced every engine), the handshake is admitted at the
    cheapest cost, the ``start`` is refused with ``server_busy`` for that request only, and
    once the engine fits, a ``start`` on the same connection gets ``ready``."""
    with serving(lerp_dir) as served:
        policy = served.state.overload.policy
        policy.limits = replace(policy.limits, session_cost=0.0, engine_costs={"viseme-lerp": 3.0})
        with client(served.ws) as ws:
            ws.send(Start("a", "viseme-lerp", "demo"))
            refused = ws.recv()
            assert isinstance(refused, ErrorMessage)
            assert (refused.code, refused.id, refused.fatal) == ("server_busy", "a", True)
            assert refused.details["reason"] == "loop_busy"
            assert "viseme-lerp" in refused.message
            assert len(policy.pending) == 0 and len(policy.priced) == 0
            policy.limits = replace(policy.limits, engine_costs={"viseme-lerp": 0.0})
            ws.send(Start("b", "viseme-lerp", "demo"))
            assert isinstance(ws.recv(), Ready)
            assert len(policy.priced) == 1 and len(policy.streaming) == 1
        # the server's side of the close runs on its own loop
        eventually(
            lambda: not (policy.priced or policy.streaming or policy.pending),
            "the closed session's admission released",
        )


def test_new_sessions_past_the_rate_are_refused_for_the_rest_of_the_window() -> None:
    """At 50 sessions a second, five fit in any 100 ms (the cost bound is out of the way):
    the sixth within the window is refused with ``admission_rate``, a verdict counts
    nothing, and once the first five are 100 ms old five more fit."""
    cheap = replace(LIMITS, session_cost=0.001, max_session_rate=50.0)
    overload = policy(cheap)
    for index in range(5):
        assert overload.verdict(QUIET, 0, 0.01 * index) is None
        assert overload.session_refusal(QUIET, 0, 0.01 * index, f"s{index}") is None
    refusal = overload.session_refusal(QUIET, 0, 0.09, "s5")
    assert refusal is not None and refusal.reason == "admission_rate"
    assert overload.verdict(QUIET, 0, 0.099) is not None and "s5" not in overload.pending
    assert RATE_RETRY_AFTER_MS <= refusal.retry_after_ms < 2 * RATE_RETRY_AFTER_MS
    # The first is 100 ms old at 0.1: one place; at 0.2 every one is, and five fit again.
    assert overload.session_refusal(QUIET, 0, 0.1, "s6") is None
    assert overload.session_refusal(QUIET, 0, 0.1, "s7") is not None
    assert admitted_in_a_burst(overload, QUIET, now=0.2) == 5
    assert admitted_in_a_burst(policy(replace(cheap, max_session_rate=0.0)), QUIET, 0.0) > 5


def test_a_verdict_learns_nothing_and_a_session_asked_about_does() -> None:
    overload = policy()
    for index in range(LEARN_FROM_SESSIONS):
        overload.set_streaming(f"s{index}", True)
    busy = LoadSample(lag_ms=1.0, loop_busy=0.32, rss_mb=100.0)
    overload.verdict(busy, 0, 5.0)
    assert overload.learned_cost == 0.0
    overload.session_refusal(busy, 0, 5.0, "new")
    assert overload.learned_cost == 0.32 / LEARN_FROM_SESSIONS
