"""``lipstream loadtest soak``: a short soak against a real loopback server, its bounds and its
accounting of memory and undocumented errors."""

from __future__ import annotations

import dataclasses
import json
import multiprocessing
import os
from collections import Counter
from pathlib import Path

import pytest

from lipstream.errors import LipstreamError
from lipstream.loadtest.hostile import HOSTILE_KINDS, HOSTILE_NICENESS, KindTally, Target
from lipstream.loadtest.sessions import ClipShare, RequestRecord
from lipstream.loadtest.soak import (
    SoakConfig,
    _hostile_process,
    _undocumented,
    check_soak,
    format_report,
    metrics_rss,
    process_tree_rss,
    soak,
)
from lipstream.results_file import write_results
from tests.helpers import run_cli
from tests.live_server import live_server

SUMMARY_KEYS = {
    "valid_frame_lag_p99_ms",
    "healthz_latency_p99_ms",
    "peak_server_rss_bytes",
    "memory_ceiling_bytes",
    "peak_rss_of_ceiling",
    "undocumented_errors",
}


def test_a_short_soak_reports_every_part_and_the_valid_sessions_complete(
    all_models_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Admission is not what this covers: on a machine busy with other tests it would refuse
    # valid sessions as the hostile kinds load the loop, so it is opened as far as it goes.
    monkeypatch.setenv("LIPSTREAM_MAX_LOOP_LAG_MS", "60000")
    monkeypatch.setenv("LIPSTREAM_MAX_LOOP_BUSY", "1")
    with live_server(all_models_dir) as served:
        config = SoakConfig(
            url=served.ws,
            duration_s=3.0,
            valid_sessions=2,
            clip_s=1.0,
            hostile_per_kind=1,
            engine="viseme-lerp",
            character="demo",
            healthz_interval_s=0.2,
            server_pid=served.pid,
            pq_phonemes=40,
            flood_seconds=2.0,
            flood_fps=100.0,
            hostile_niceness=0,  # on a machine busy with other tests a 3 s attack must run
        )
        results = soak(config, command="lipstream loadtest soak --duration 3")
    valid = results["valid"]
    # Each session starts a 1 s clip within its first second, so both run at least one;
    # a 1 s clip at 60 fps has floor(1.0 * 60) + 1 = 61 frames, then 9 of return to rest.
    # A valid request the server still turned away for load must have been told so
    # (`server_busy` or HTTP 503, both retryable); every other one completes with all its
    # frames.
    assert valid["requests"] >= 2 and valid["successful_requests"] >= 1
    assert set(valid["errors"]) <= {"server_busy", "http_503"}
    refused = sum(valid["errors"].values())
    assert valid["successful_requests"] + refused == valid["requests"]
    assert valid["frames"] == (61 + 9) * valid["successful_requests"]
    lag = valid["frame_lag_ms"]
    assert lag["p50"] <= lag["p95"] <= lag["p99"] <= lag["max"]
    assert results["healthz"]["polls"] >= 1
    assert set(results["healthz"]["latency_ms"]) == {"p50", "mean", "p95", "p99", "max"}
    memory = results["server_memory"]
    assert memory["source"] == f"/proc/{served.pid}" and memory["samples"] >= 1
    assert memory["peak_rss_bytes"] > 0
    summary = results["summary"]
    assert memory["ceiling_bytes"] == summary["memory_ceiling_bytes"] > 0
    assert summary["peak_rss_of_ceiling"] == memory["peak_rss_bytes"] / memory["ceiling_bytes"]
    assert results["command"] == "lipstream loadtest soak --duration 3"
    assert results["date"].endswith("+00:00")
    assert set(results["hostile"]) == set(HOSTILE_KINDS)
    for kind, tally in results["hostile"].items():
        assert tally["attempts"] >= 1, kind
        assert set(tally) == {"attempts", "error_codes", "closes", "client_failures", "skipped"}
    assert results["hostile"]["pq_search"]["skipped"] is None  # the demo has anime-graph
    assert results["hostile"]["pq_connections"]["skipped"] is None
    assert results["hostile"]["client_flood"]["skipped"] is None  # the server is on 127.0.0.1
    assert results["hostile"]["big_heads"]["closes"].get("http_431", 0) >= 1
    assert isinstance(results["undocumented_errors"], dict)
    assert set(results["summary"]) == SUMMARY_KEYS
    assert results["summary"]["valid_frame_lag_p99_ms"] == lag["p99"]
    assert results["config"]["token"] is None
    write_results(results, tmp_path / "bench" / "soak.json")
    assert json.loads((tmp_path / "bench" / "soak.json").read_text()) == results
    report = format_report(results)
    assert "valid sessions:" in report and all(kind in report for kind in HOSTILE_KINDS)


@pytest.mark.parametrize(
    ("change", "flag"),
    [
        ({"url": "ws://192.0.2.1:8000/v1/stream"}, "--url"),
        ({"duration_s": 0.0}, "--duration"),
        ({"duration_s": 3601.0}, "--duration"),
        ({"valid_sessions": 0}, "--valid-sessions"),
        ({"kinds": ("silent_tcp", "nonsense")}, "--kinds"),
        ({"hostile_per_kind": 101}, "--hostile"),
        ({"flood_fps": 2000.0}, "--flood-fps"),
        ({"hostile_niceness": 20}, "--hostile-niceness"),
        ({"server_pid": 2**31 - 1}, "--server-pid"),
    ],
)
def test_bounds_name_the_flag(change: dict[str, object], flag: str) -> None:
    config = dataclasses.replace(SoakConfig(), **change)  # type: ignore[arg-type]  # bad values on purpose
    with pytest.raises(LipstreamError) as refused:
        check_soak(config)
    assert refused.value.where == flag


def test_the_cli_refuses_a_remote_target_with_one_line(tmp_path: Path) -> None:
    result = run_cli(
        "loadtest", "soak", "--url", "ws://192.0.2.1:8000/v1/stream", "--results", str(tmp_path)
    )
    assert result.returncode == 2
    assert result.stderr.startswith("error [not_loopback]: --url:")
    assert len(result.stderr.strip().splitlines()) == 1


def test_memory_comes_from_proc_or_from_the_metrics_exposition() -> None:
    status = Path(f"/proc/{os.getpid()}/status").read_text()
    own_kib = next(int(line.split()[1]) for line in status.splitlines() if line[:6] == "VmRSS:")
    rss = process_tree_rss(os.getpid())
    assert rss is not None and rss >= 0.5 * own_kib * 1024
    exposition = (
        "# HELP process_resident_memory_bytes Resident memory size in bytes.\n"
        "# TYPE process_resident_memory_bytes gauge\n"
        'process_resident_memory_bytes{pid="1"} 1.5e+08\n'
        'process_resident_memory_bytes{pid="2"} 5e+07\n'
        "lipstream_sessions 3.0\n"
    )
    assert metrics_rss(exposition) == 200_000_000
    assert metrics_rss("lipstream_sessions 3.0\n") is None


def test_only_codes_outside_the_documented_tables_are_undocumented() -> None:
    share = ClipShare(
        records=[
            RequestRecord(error=None),
            RequestRecord(error="malformed"),  # documented error code
            RequestRecord(error="closed_1011"),  # documented close code
            RequestRecord(error="closed_4000"),
            RequestRecord(error="timeout"),  # the client's own
            RequestRecord(error="TimeoutError"),
            RequestRecord(error="deadline"),
        ]
    )
    tally = KindTally()
    tally.error_codes.update({"malformed": 3, "weird_code": 2, "no_error_reply": 1})
    tally.closes.update({"1008": 1, "4999": 1, "reset": 2, "http_408": 1})
    assert _undocumented(share, {"malformed": tally.as_dict()}) == {
        "closed_4000": 1,
        "closed_4999": 1,
        "weird_code": 2,
    }


def test_the_hostile_process_yields_the_core_to_the_measuring_one(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Run in this process with no kinds: it lowers its priority before any attack, and
    reports its (empty) tallies through the pipe."""
    niced: list[int] = []

    def nice(increment: int) -> int:
        niced.append(increment)
        return increment

    monkeypatch.setattr(os, "nice", nice)
    receiving, sending = multiprocessing.Pipe(duplex=False)
    target = Target(
        "ws://127.0.0.1:9/v1/stream",
        "127.0.0.1",
        9,
        "viseme-lerp",
        "demo",
        "msgpack",
        None,
        None,
        None,
        10,
        1.0,
        60.0,
        0,
    )
    _hostile_process(SoakConfig(kinds=()), target, 0.0, sending)
    assert niced == [HOSTILE_NICENESS] and HOSTILE_NICENESS > 0
    assert json.loads(receiving.recv_bytes()) == {}
    receiving, sending = multiprocessing.Pipe(duplex=False)
    _hostile_process(SoakConfig(kinds=(), hostile_niceness=0), target, 0.0, sending)
    assert niced == [HOSTILE_NICENESS]  # 0: the attack keeps the measuring clients' priority
    assert json.loads(receiving.recv_bytes()) == {}


def test_a_reader_let_go_by_a_reset_is_counted_as_the_documented_reset() -> None:
    from lipstream.loadtest.hostile import stopped_reader_close

    assert stopped_reader_close(1006) == "reset"
    assert stopped_reader_close(1008) == "1008"
    hostile = {"stops_reading": KindTally(closes=Counter({"reset": 2})).as_dict()}
    assert _undocumented(ClipShare(), hostile) == {}
    hostile = {"stops_reading": KindTally(closes=Counter({"1006": 2})).as_dict()}
    assert _undocumented(ClipShare(), hostile) == {"closed_1006": 2}
