"""What one connection costs a running server's CPU: a WebSocket opened and closed, and an
HTTP ``GET /healthz`` on a connection of its own.

Method: a client opens ``--connections`` WebSockets to ``/v1/stream`` one after another
(the handshake, then a close at once: no request), and as many HTTP connections each asking
``/healthz``; the server's CPU time (user + system, from ``/proc/<pid>/stat`` of
``--server-pid``) is read before and after each leg, and each leg's cost is that
difference per connection. The legs alternate over ``--rounds`` so that a machine's drift
reaches both. Run the server alone on its core (``taskset``), with the per-client upgrade
rate and the session rate off (``LIPSTREAM_CLIENT_UPGRADE_RATE=0``,
``LIPSTREAM_MAX_SESSION_RATE=0``), since the legs come from one address, one after another.

    python -m lipstream.bench.connection_cost --url ws://127.0.0.1:8000/v1/stream \\
        --server-pid PID [--connections 400] [--rounds 2] [--json bench/connection_cost.json]
"""

from __future__ import annotations

import argparse
import http.client
import statistics
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from websockets.sync.client import connect

from lipstream_client.codec import SUBPROTOCOL_JSON

from ..loadtest.cpu import cpu_seconds
from ..results_file import recorded, script_command, write_results

LEGS = ("websocket", "healthz")


def open_websocket(url: str) -> None:
    with connect(url, subprotocols=[SUBPROTOCOL_JSON]):  # type: ignore[list-item]
        pass


def ask_healthz(url: str) -> None:
    parts = urlsplit(url)
    connection = http.client.HTTPConnection(parts.hostname or "127.0.0.1", parts.port or 80)
    try:
        connection.request("GET", "/healthz")
        connection.getresponse().read()
    finally:
        connection.close()


def leg_cost_ms(server_pid: int, connections: int, once: Callable[[], None]) -> float:
    """Server CPU milliseconds per call of ``once``, over ``connections`` calls."""
    before = cpu_seconds([server_pid])
    for _ in range(connections):
        once()
    after = cpu_seconds([server_pid])
    if before is None or after is None:
        raise RuntimeError(f"cannot read /proc/{server_pid}/stat")
    return 1000.0 * (after - before) / connections


def measure(url: str, server_pid: int, connections: int, rounds: int) -> dict[str, Any]:
    """Each leg's cost per connection in every round, and its median."""
    calls = {"websocket": lambda: open_websocket(url), "healthz": lambda: ask_healthz(url)}
    costs: dict[str, list[float]] = {leg: [] for leg in LEGS}
    for _ in range(rounds):
        for leg in LEGS:
            costs[leg].append(leg_cost_ms(server_pid, connections, calls[leg]))
    return {
        leg: {"cpu_ms_per_connection": values, "median_ms": statistics.median(values)}
        for leg, values in costs.items()
    }


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m lipstream.bench.connection_cost")
    parser.add_argument("--url", required=True, help="the server's ws://.../v1/stream")
    parser.add_argument("--server-pid", type=int, required=True)
    parser.add_argument("--connections", type=int, default=400)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--json", type=Path, default=None, help="write the results here")
    arguments = parser.parse_args(argv)
    results = recorded(script_command("lipstream.bench.connection_cost", argv))
    results["connections"] = arguments.connections
    results["rounds"] = arguments.rounds
    results["legs"] = measure(
        arguments.url, arguments.server_pid, arguments.connections, arguments.rounds
    )
    for leg, figures in results["legs"].items():
        print(f"{leg}: {figures['median_ms']:.2f} ms of server CPU per connection")
    if arguments.json is not None:
        write_results(results, arguments.json)


if __name__ == "__main__":
    main()
