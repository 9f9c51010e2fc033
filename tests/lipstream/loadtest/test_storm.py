"""The storm tool on a small scale against a real server (the storm figures are measured
outside the suite), and its client-clock lag, refusal tally and results file by hand."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path

import pytest

from lipstream.config import ServerSettings
from lipstream.loadtest.storm import (
    PHONEME_S,
    _quantile,
    block_lag_ms,
    refusals,
    storm,
    storm_results,
    write_storm_results,
)
from tests.lipstream.server.harness import serving


def test_silent_and_partial_connections_are_reported_closed_by_the_server(
    lerp_dir: Path,
) -> None:
    with serving(lerp_dir, ServerSettings(handshake_timeout_s=0.3)) as served:
        silent = asyncio.run(storm(served.ws, "silent", 5, duration_s=10.0))
        partial = asyncio.run(storm(served.ws, "partial", 5, duration_s=10.0))
    assert silent.outcomes == {"closed_by_server": 5}
    assert partial.outcomes == {"closed_by_server": 5}
    probe = silent.healthz["serving"]
    assert probe.probes >= 1 and probe.failed == 0 and probe.latency_ms["p99"] is not None


def test_sessions_past_the_cap_are_counted_by_reason_with_the_lag_on_the_clients_clock(
    lerp_dir: Path,
) -> None:
    settings = ServerSettings(max_sessions=2, max_memory_mb=4000)
    with serving(lerp_dir, settings) as served:
        health = f"{served.http}/healthz"  # a second probe: the same port stands in here
        report = asyncio.run(
            storm(served.ws, "sessions", 5, 0.8, health_port_url=health, baseline=1)
        )
    assert report.outcomes == {"finished": 1, "server_busy:sessions": 4, "baseline:finished": 1}
    assert report.refusals == {"sessions": 4} and report.admitted == 1
    # 0.8 s of phonemes, one per 80 ms, each answered by frames: blocks from both sessions.
    assert report.lag_blocks >= 2 * round(0.8 / PHONEME_S)
    lag = report.lag_ms
    assert lag["p50"] is not None and lag["p99"] is not None and 0.0 <= lag["p50"] <= lag["p99"]
    assert report.baseline_lag_ms["p99"] is not None
    assert report.client_loop_lag_ms["max"] is not None
    assert report.server_lag_p99_s is not None
    assert set(report.healthz) == {"serving", "health_port"}
    assert all(probe.probes >= 1 and probe.failed == 0 for probe in report.healthz.values())
    assert report.memory_ceiling_mb == 4000.0
    assert report.peak_rss_mb is not None and 10.0 < report.peak_rss_mb < 4000.0


def test_the_storm_is_shared_among_client_processes(lerp_dir: Path) -> None:
    with serving(lerp_dir, ServerSettings(max_sessions=3)) as served:
        report = asyncio.run(storm(served.ws, "sessions", 7, 0.5, processes=3))
    # 7 connections as 3 + 2 + 2, over processes that each lag-time their own loop
    assert report.outcomes == {"finished": 3, "server_busy:sessions": 4}
    assert report.admitted == 3 and report.processes == 3
    assert report.lag_blocks >= 3 * round(0.5 / PHONEME_S)
    assert report.client_loop_lag_ms["p50"] is not None
    with pytest.raises(ValueError, match="processes"):
        asyncio.run(storm(served.ws, "sessions", 1, processes=0))


def test_sessions_ask_for_the_latency_budget_given(lerp_dir: Path) -> None:
    """A budget below every rung's need reaches the server: it refuses each session with
    ``budget_infeasible``, which the storm counts as a failure of that kind."""
    with serving(lerp_dir, ServerSettings()) as served:
        report = asyncio.run(storm(served.ws, "sessions", 2, 0.5, latency_budget_ms=0.01))
    assert report.outcomes == {"error:budget_infeasible": 2}
    assert report.refusals == {"budget_infeasible": 2} and report.admitted == 0


def test_a_blocks_lag_runs_from_the_send_of_the_message_covering_its_first_frame() -> None:
    sent = [10.0, 10.08, 10.16, 10.30]  # three phonemes, then end
    # 60 fps: frame 5 is at 0.0833 s, in the second phoneme's span [0.08, 0.16)
    assert block_lag_ms(5, 60.0, sent, 10.1) == pytest.approx(20.0)
    assert block_lag_ms(0, 60.0, sent, 10.005) == pytest.approx(5.0)
    # frame 12 at 0.2 s, in the third phoneme's span
    assert block_lag_ms(12, 60.0, sent, 10.2) == pytest.approx(40.0)
    # frame 48 at 0.8 s, past every phoneme: covered by end
    assert block_lag_ms(48, 60.0, sent, 10.31) == pytest.approx(10.0)
    assert block_lag_ms(0, 60.0, [], 1.0) is None


def test_refusals_are_tallied_by_reason() -> None:
    outcomes = ["finished", "server_busy:loop_busy", "server_busy:loop_busy", "http_503"]
    outcomes += ["server_busy:receive_lag", "error:budget_infeasible", "failed:OSError"]
    assert refusals(outcomes) == {
        "loop_busy": 2,
        "http_503": 1,
        "receive_lag": 1,
        "budget_infeasible": 1,
    }


def test_a_run_is_added_to_the_results_file_beside_the_others(tmp_path: Path) -> None:
    from lipstream.loadtest.storm import StormReport

    path = tmp_path / "storm.json"
    path.write_text(json.dumps({"earlier": {"kept": True}}))
    results = storm_results(StormReport("sessions", 3), ["lipstream", "loadtest", "storm"])
    write_storm_results(results, path, "client_clock")
    written = json.loads(path.read_text())
    assert written["earlier"] == {"kept": True}
    run = written["client_clock"]
    assert run["command"] == "lipstream loadtest storm"
    assert run["machine"]["cores"] >= 1 and run["date"].startswith("20")
    assert run["report"]["kind"] == "sessions" and run["report"]["connections"] == 3


def test_quantiles_are_the_bucket_bounds_they_fall_under() -> None:
    cumulative = {0.01: 50.0, 0.1: 98.0, 1.0: 100.0, float("inf"): 100.0}
    assert _quantile(cumulative, 0.5) == 0.01
    assert _quantile(cumulative, 0.99) == 1.0
    assert _quantile({float("inf"): 0.0}, 0.5) is None
