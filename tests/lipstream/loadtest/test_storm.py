"""The storm tool on a small scale against a real server (the storm figures are measured
outside the suite)."""

from __future__ import annotations

import asyncio
from pathlib import Path

from lipstream.config import ServerSettings
from lipstream.loadtest.storm import _quantile, storm
from tests.lipstream.server.harness import serving


def test_silent_and_partial_connections_are_reported_closed_by_the_server(
    lerp_dir: Path,
) -> None:
    with serving(lerp_dir, ServerSettings(handshake_timeout_s=0.3)) as served:
        silent = asyncio.run(storm(served.ws, "silent", 5, duration_s=10.0))
        partial = asyncio.run(storm(served.ws, "partial", 5, duration_s=10.0))
    assert silent.outcomes == {"closed_by_server": 5}
    assert partial.outcomes == {"closed_by_server": 5}
    assert silent.probes >= 1 and silent.probes_failed == 0


def test_sessions_past_the_cap_are_counted_by_reason(lerp_dir: Path) -> None:
    with serving(lerp_dir, ServerSettings(max_sessions=2)) as served:
        report = asyncio.run(storm(served.ws, "sessions", 5, duration_s=0.8))
    assert report.outcomes == {"finished": 2, "server_busy:sessions": 3}
    assert report.lag_p99_s is not None and report.lag_p50_s is not None
    assert report.lag_p50_s <= report.lag_p99_s


def test_sessions_ask_for_the_latency_budget_given(lerp_dir: Path) -> None:
    """A budget below every rung's need reaches the server: it refuses each session with
    ``budget_infeasible``, which the storm counts as a failure of that kind."""
    with serving(lerp_dir, ServerSettings()) as served:
        report = asyncio.run(storm(served.ws, "sessions", 2, 0.5, latency_budget_ms=0.01))
    assert report.outcomes == {"error:budget_infeasible": 2}


def test_quantiles_are_the_bucket_bounds_they_fall_under() -> None:
    cumulative = {0.01: 50.0, 0.1: 98.0, 1.0: 100.0, float("inf"): 100.0}
    assert _quantile(cumulative, 0.5) == 0.01
    assert _quantile(cumulative, 0.99) == 1.0
    assert _quantile({float("inf"): 0.0}, 0.5) is None
