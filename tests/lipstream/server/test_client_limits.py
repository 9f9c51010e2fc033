"""Per-client limits: the sans-I/O accounting with an injected clock, and a real server on
loopback refusing one address's connection past its cap and its upgrades past its rate with
``too_many_client_connections``, while ``/healthz`` answers."""

from __future__ import annotations

import json
import re
from collections.abc import Iterator
from contextlib import ExitStack
from pathlib import Path

import httpx
import pytest
from websockets.exceptions import InvalidStatus

from lipstream.config import ServerSettings, load_server_settings
from lipstream.server.client_limits import CONNECTIONS, UPGRADE_RATE, ClientLimits
from lipstream_client import Done, End, PhonemeItem, Phonemes, Start
from lipstream_client.errors import ERROR_CODES, TOO_MANY_CLIENT_CONNECTIONS
from tests.lipstream.server.harness import Client, Served, client, serving

CAP = 3
ATTEMPTS = 200
HOST = "127.0.0.1"


def test_the_connection_after_the_cap_is_over_it_until_one_closes() -> None:
    limits = ClientLimits(max_connections=CAP, upgrade_rate=0.0, upgrade_burst=1)
    assert [limits.opened(HOST, 0.0) for _ in range(CAP + 1)] == [True] * CAP + [False]
    assert limits.opened("127.0.0.2", 0.0)  # another address has its own count
    limits.closed(HOST, 0.0)
    limits.closed(HOST, 0.0)
    assert limits.opened(HOST, 0.0) and not limits.opened(HOST, 0.0)


def test_upgrades_follow_a_token_bucket_on_the_injected_clock() -> None:
    limits = ClientLimits(max_connections=0, upgrade_rate=2.0, upgrade_burst=3)
    assert [limits.upgrade(HOST, 10.0) for _ in range(4)] == [True, True, True, False]
    assert not limits.upgrade(HOST, 10.25)  # half a token
    assert limits.upgrade(HOST, 10.5) and not limits.upgrade(HOST, 10.5)
    # A long pause refills the bucket to its burst, no further.
    assert [limits.upgrade(HOST, 100.0) for _ in range(4)] == [True, True, True, False]
    assert limits.retry_after_s(UPGRADE_RATE) == 1 and limits.retry_after_s(CONNECTIONS) == 1
    assert ClientLimits(0, 0.1, 1).retry_after_s(UPGRADE_RATE) == 10


def test_idle_addresses_are_forgotten_once_their_bucket_is_full() -> None:
    limits = ClientLimits(max_connections=5, upgrade_rate=1.0, upgrade_burst=2)
    limits.opened(HOST, 0.0)
    assert limits.upgrade(HOST, 0.0)
    limits.closed(HOST, 0.5)  # half a token short of full: kept
    assert HOST in limits.clients
    for index in range(limits.sweep_at - 1):  # refused-and-gone clients, a token short
        address = f"10.0.{index // 256}.{index % 256}"
        limits.opened(address, 5.0)
        assert limits.upgrade(address, 5.0)
        limits.closed(address, 5.0)
    assert len(limits.clients) == limits.sweep_at
    # The table is full: a new address sweeps it, and every bucket has refilled by then.
    assert limits.opened("192.0.2.1", 10.0)
    assert list(limits.clients) == ["192.0.2.1"]
    assert ClientLimits(0, 0.0, 1).upgrade(HOST, 0.0)  # no limit


def test_the_settings_are_read_from_the_environment() -> None:
    settings = load_server_settings(
        {
            "LIPSTREAM_MAX_CLIENT_CONNECTIONS": "7",
            "LIPSTREAM_CLIENT_UPGRADE_RATE": "2.5",
            "LIPSTREAM_CLIENT_UPGRADE_BURST": "9",
        }
    )
    limits = ClientLimits.from_settings(settings)
    assert (limits.max_connections, limits.upgrade_rate, limits.upgrade_burst) == (7, 2.5, 9)
    assert ERROR_CODES[TOO_MANY_CLIENT_CONNECTIONS].scope == "connection"


def refusal(served: Served) -> tuple[int, dict[str, object], str | None]:
    """Status, JSON error and Retry-After of a WebSocket upgrade the server refuses."""
    with pytest.raises(InvalidStatus) as refused:
        with client(served.ws):
            pass
    response = refused.value.response
    error = json.loads(response.body or b"")["error"]
    return response.status_code, error, response.headers.get("Retry-After")


def a_request_is_served(ws: Client, identifier: str = "r") -> None:
    ws.send(
        Start(identifier, "viseme-lerp", "demo", fps=60),
        Phonemes(identifier, (PhonemeItem("HH", 0.0, 0.1), PhonemeItem("AY1", 0.1, 0.3))),
        End(identifier),
    )
    assert isinstance(ws.until_done(identifier)[-1], Done)


def metric(served: Served, name: str) -> float:
    found = re.search(rf"^{re.escape(name)} (\S+)$", httpx.get(f"{served.http}/metrics").text, re.M)
    return float(found.group(1)) if found else 0.0


@pytest.fixture(scope="module")
def capped(lerp_dir: Path) -> Iterator[Served]:
    settings = ServerSettings(max_client_connections=CAP, handshake_timeout_s=60.0)
    with serving(lerp_dir, settings) as served:
        yield served


def test_one_connection_past_a_clients_cap_is_refused_and_healthz_answers(
    capped: Served,
) -> None:
    with ExitStack() as stack:
        sessions = [stack.enter_context(client(capped.ws)) for _ in range(CAP)]
        status, error, retry_after = refusal(capped)
        assert (status, error["code"], retry_after) == (503, TOO_MANY_CLIENT_CONNECTIONS, "1")
        assert error["details"] == {
            "reason": "connections",
            "retry_after_ms": 1000,
            "max_client_connections": CAP,
        }
        # A plain request over the cap is refused the same way; /healthz is answered.
        over = httpx.get(f"{capped.http}/v1/engines")
        assert over.status_code == 503
        assert over.json()["error"]["code"] == TOO_MANY_CLIENT_CONNECTIONS
        assert httpx.get(f"{capped.http}/healthz").json() == {"status": "ok"}
        a_request_is_served(sessions[0])  # the admitted ones are unharmed
    # Once they close, new connections are admitted (bounded: the server sees the closes
    # when its loop gets to them).
    for _ in range(ATTEMPTS):
        try:
            with client(capped.ws) as ws:
                a_request_is_served(ws)
            break
        except InvalidStatus:
            continue
    else:
        raise AssertionError("no connection was admitted after the others closed")
    name = 'lipstream_client_refusals_total{reason="connections"}'
    assert metric(capped, name) >= 2


def test_upgrades_past_a_clients_rate_are_refused(lerp_dir: Path) -> None:
    # A rate so low that no token comes back during the test: the burst, then refusals.
    settings = ServerSettings(client_upgrade_rate=0.001, client_upgrade_burst=2)
    with serving(lerp_dir, settings) as served:
        for _ in range(2):
            with client(served.ws) as ws:
                a_request_is_served(ws)
        status, error, retry_after = refusal(served)
        assert (status, error["code"], retry_after) == (503, TOO_MANY_CLIENT_CONNECTIONS, "1000")
        assert error["details"] == {
            "reason": "upgrade_rate",
            "retry_after_ms": 1_000_000,
            "client_upgrade_rate": 0.001,
        }
        assert httpx.get(f"{served.http}/healthz").json() == {"status": "ok"}
        assert httpx.get(f"{served.http}/v1/engines").status_code == 200  # HTTP is not upgrades
        name = 'lipstream_client_refusals_total{reason="upgrade_rate"}'
        assert metric(served, name) == 1.0


def test_whether_an_address_is_out_of_upgrades_is_told_without_taking_a_token() -> None:
    limits = ClientLimits(max_connections=0, upgrade_rate=2.0, upgrade_burst=1)
    assert not limits.out_of_upgrades(HOST, 0.0)  # an address not seen has a full bucket
    assert limits.upgrade(HOST, 0.0)
    assert limits.out_of_upgrades(HOST, 0.0) and limits.out_of_upgrades(HOST, 0.25)
    assert not limits.out_of_upgrades(HOST, 0.5)  # at 2 a second, one token is back
    assert limits.upgrade(HOST, 0.5) and not limits.upgrade(HOST, 0.5)  # the checks took none
    assert not ClientLimits(0, 0.0, 1).out_of_upgrades(HOST, 0.0)  # no rate, never out
