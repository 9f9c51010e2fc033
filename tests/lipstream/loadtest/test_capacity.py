"""The capacity search, the multi-process load generator and the first-frame probe."""

from __future__ import annotations

import json
import math
from array import array
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from lipstream.errors import InvalidRequestError, LipstreamError
from lipstream.loadtest.capacity import (
    CapacitySearch,
    check_search,
    find_capacity,
    merge_results,
    next_probe,
    probe_summary,
    record_search,
)
from lipstream.loadtest.load import LoadTestConfig, loadtest
from lipstream.loadtest.reference import ReferenceTraffic
from lipstream.loadtest.sessions import ClipShare, RequestRecord
from lipstream.loadtest.workers import decode_share, encode_share, split
from tests.lipstream_client.fake_server import FakeServer

REFERENCE_URL = "ws://127.0.0.1:9/v1/stream"
BASE = LoadTestConfig(engine="viseme-lerp", character="demo", workers=2, probe_phonemes=30)


def _results(
    streams: int, p99_ms: float, failed: int = 0, at_once: int | None = None
) -> dict[str, Any]:
    """A load-test document as ``loadtest`` shapes it, for a fake run."""
    lag = {
        "p50": p99_ms - 40.0,
        "mean": p99_ms - 40.0,
        "p95": p99_ms - 5.0,
        "p99": p99_ms,
        "max": p99_ms + 30.0,
    }
    clip = {
        "requests": streams,
        "successful_requests": streams - failed,
        "errors": {"timeout": failed} if failed else {},
        "peak_sessions": streams if at_once is None else at_once,
        "busy_retries": 0,
        "frame_lag_ms": lag,
        "first_packet_latency_ms": {"p50": 1.0, "p99": 2.0, "max": 3.0},
        "fps": {"p1": 59.0},
        "send_slip_ms": {"p99": 1.0},
        "probe": {
            "phonemes": 30,
            "requests": 40,
            "first_frame_latency_ms": {"p50": 4.0, "p99": 9.0, "max": 12.0},
        },
        "wall_s": 11.0,
        "client_cpu_s": 5.5,
        "server_cpu_s": 8.8,
    }
    return {"clips": [clip], "summary": {"server_processes": 1}}


def test_the_search_doubles_then_bisects_to_the_resolution() -> None:
    search = CapacitySearch(BASE, start=100, max_streams=1000, resolution=25)
    verdicts: dict[int, bool] = {}
    order = []
    while (streams := next_probe(verdicts, search)) is not None:
        order.append(streams)
        verdicts[streams] = streams <= 437  # the server's true limit
    # By hand: 100, 200, 400 pass; 800 fails; then 600, 500, 450 fail and 425 passes,
    # leaving 425..450, within the resolution of 25.
    assert order == [100, 200, 400, 800, 600, 500, 450, 425]


def test_the_search_stops_at_the_maximum_and_reports_zero_when_nothing_passes() -> None:
    search = CapacitySearch(BASE, start=300, max_streams=1000, resolution=25)
    verdicts: dict[int, bool] = {}
    while (streams := next_probe(verdicts, search)) is not None:
        verdicts[streams] = True
    assert sorted(verdicts) == [300, 600, 1000]
    verdicts = {}
    while (streams := next_probe(verdicts, search)) is not None:
        verdicts[streams] = False
    # Halving from 300, each middle rounded down to a multiple of 25: 150, 75, then 37 -> 25.
    assert sorted(verdicts) == [25, 75, 150, 300]


def test_find_capacity_runs_probes_and_documents_the_boundary() -> None:
    configs: list[LoadTestConfig] = []

    def run(config: LoadTestConfig) -> dict[str, Any]:
        configs.append(config)
        p99 = -30.0 + max(0, config.streams - 300) * 0.5  # crosses 50 ms at 460 sessions
        return _results(config.streams, p99)

    search = CapacitySearch(
        BASE, start=100, max_streams=1000, resolution=25, pause_s=0.0, reference=False
    )
    document = find_capacity(search, run)
    assert [c.streams for c in configs] == [1, 100, 200, 400, 800, 600, 500, 450, 475]
    assert all(c.requests == 2 * c.streams and c.clips_s == (10.0,) for c in configs)
    assert [c.workers for c in configs[:2]] == [1, 2]  # never more processes than sessions
    assert document["capacity_streams"] == 450 and document["upper_bound_streams"] == 475
    assert document["idle"]["streams"] == 1 and document["idle"]["passed"]
    assert document["at_capacity"]["frame_lag_ms"]["p99"] == pytest.approx(45.0)
    assert document["at_capacity"]["server_cores"] == pytest.approx(0.8)
    assert document["at_capacity"]["probe_first_frame_latency_ms"]["p99"] == 9.0
    assert document["server_processes"] == 1 and document["lead_ms"] == 0.0
    assert "reference" not in document


def test_the_reference_is_searched_once_per_traffic_and_the_ratio_is_engine_over_it() -> None:
    urls: list[str] = []
    served: list[tuple[ReferenceTraffic, int]] = []
    traffic = ReferenceTraffic(("jawOpen", "mouthClose"), 0.0, "causal")

    def run(config: LoadTestConfig) -> dict[str, Any]:
        urls.append(config.url)
        crossing = 600 if config.url == REFERENCE_URL else 300  # where p99 crosses 50 ms
        results = _results(config.streams, 50.0 * config.streams / crossing - 0.01)
        results["summary"]["server_processes"] = 3  # a supervisor and two workers
        return results

    @contextmanager
    def serve(traffic: ReferenceTraffic, workers: int) -> Iterator[str]:
        served.append((traffic, workers))
        yield REFERENCE_URL

    search = CapacitySearch(BASE, start=100, max_streams=1000, resolution=25, pause_s=0.0)
    references: dict[Any, dict[str, Any]] = {}
    documents = [
        find_capacity(
            replace(search, base=replace(BASE, engine=engine)),
            run,
            None,
            lambda base: traffic,
            serve,
            references,
        )
        for engine in ("viseme-lerp", "dam")
    ]
    assert served == [(traffic, 2)]  # one reference search, as many workers as the server
    assert urls.count(REFERENCE_URL) == len(documents[0]["reference"]["probes"]) + 1
    for document in documents:
        assert document["capacity_streams"] == 300
        assert document["reference"]["capacity_streams"] == 600
        assert list(document["reference"]["traffic"]["channels"]) == ["jawOpen", "mouthClose"]
        assert document["capacity_ratio"] == pytest.approx(0.5)


def test_a_probe_with_failed_requests_fails_however_low_its_lag() -> None:
    assert probe_summary(10, _results(10, 5.0), 50.0)["passed"]
    assert not probe_summary(10, _results(10, 5.0, failed=1), 50.0)["passed"]
    assert not probe_summary(10, _results(10, 50.0), 50.0)["passed"]


def test_a_probe_whose_sessions_never_all_stream_at_once_fails() -> None:
    """Admission can spread a burst into waves: 10 sessions whose requests succeed with 9 at
    most held together did not show that 10 are held."""
    assert not probe_summary(10, _results(10, 5.0, at_once=9), 50.0)["passed"]
    assert probe_summary(10, _results(10, 5.0, at_once=10), 50.0)["passed"]


def test_searches_accumulate_in_one_file_by_key(tmp_path: Path) -> None:
    path = tmp_path / "capacity.json"
    key = {
        "engine": "viseme-lerp",
        "character": "demo",
        "fps": 60.0,
        "lead_ms": 300.0,
        "clip_s": 10.0,
        "encoding": "msgpack",
        "server_processes": 1,
    }
    path.write_text(json.dumps(merge_results(path, {**key, "capacity_streams": 400})))
    other = {**key, "engine": "anime-graph", "capacity_streams": 200}
    path.write_text(json.dumps(merge_results(path, other)))
    document = merge_results(path, {**key, "capacity_streams": 575})
    assert [(s["engine"], s["capacity_streams"]) for s in document["searches"]] == [
        ("anime-graph", 200),
        ("viseme-lerp", 575),
    ]
    path.write_text(json.dumps(document))
    budgeted = merge_results(path, {**key, "latency_budget_ms": 20.0, "capacity_streams": 90})
    assert [s["capacity_streams"] for s in budgeted["searches"]] == [200, 575, 90]


def test_the_file_dates_itself_by_its_searches_and_keeps_its_notes(tmp_path: Path) -> None:
    path = tmp_path / "capacity.json"
    command = "lipstream loadtest capacity --engine all --character demo"
    first = {"engine": "dam", "date": "2026-12-05T00:10:00+00:00", "command": command}
    path.write_text(json.dumps({**merge_results(path, first), "note": "quiet machine"}))
    second = {"engine": "hmm", "date": "2026-12-05T00:20:00+00:00", "command": command}
    document = merge_results(path, second)
    assert document["date"] == "2026-12-05T00:10:00+00:00 to 2026-12-05T00:20:00+00:00"
    assert document["command"] == command and document["note"] == "quiet machine"
    path.write_text(json.dumps(document))
    other = {"engine": "dam", "date": "2026-12-05T00:30:00+00:00", "command": command + " -x"}
    mixed = merge_results(path, other)  # replaces dam's search: hmm's date is now the first
    assert mixed["date"] == "2026-12-05T00:20:00+00:00 to 2026-12-05T00:30:00+00:00"
    assert "command" not in mixed  # each search keeps its own


def test_a_results_file_of_another_shape_is_refused_not_overwritten(tmp_path: Path) -> None:
    path = tmp_path / "figures.json"
    original = json.dumps({"note": "hand-made figures", "two_workers": [{"streams": 150}]})
    path.write_text(original)
    with pytest.raises(LipstreamError) as refused:
        merge_results(path, {"engine": "viseme-lerp", "capacity_streams": 400})
    assert refused.value.code == "invalid_results_file" and refused.value.where == str(path)
    path.write_text("[1, 2")
    with pytest.raises(LipstreamError) as unreadable:
        merge_results(path, {"engine": "viseme-lerp", "capacity_streams": 400})
    assert unreadable.value.code == "invalid_results_file"
    path.write_text(original)
    with pytest.raises(LipstreamError):
        record_search(path, {"engine": "viseme-lerp", "capacity_streams": 400})
    assert path.read_text() == original


def test_search_bounds_are_checked() -> None:
    with pytest.raises(InvalidRequestError) as refused:
        check_search(CapacitySearch(BASE, start=0))
    assert refused.value.where == "--start"
    with pytest.raises(InvalidRequestError) as refused:
        check_search(CapacitySearch(BASE, max_streams=5000))
    assert refused.value.where == "--streams"


def test_a_share_crosses_the_process_boundary_intact() -> None:
    share = ClipShare(
        records=[
            RequestRecord(),
            RequestRecord(error="timeout", frames=3, send_slip_ms=[0.5, 1.25]),
            RequestRecord(frames=2, streaming_s=[100.25, 110.5]),
        ],
        block_lag_ms=array("d", [10.0, -2.5]),
        block_frames=array("q", [3, 1]),
        probe_ms=[4.0],
        probe_errors=["server_busy"],
        cpu_s=1.5,
        session_spans=[(100.25, 121.0)],
    )
    assert decode_share(*encode_share(share)) == share
    # Row r of a block is scheduled r / fps after its first frame: at 50 fps, 20 ms each.
    assert list(share.frame_lags_ms(50.0)) == [10.0, -10.0, -30.0, -2.5]
    assert [split(7, 3, part) for part in range(3)] == [3, 2, 2]


def test_two_worker_processes_and_the_probe_measure_every_request() -> None:
    with FakeServer() as server:
        config = LoadTestConfig(
            url=server.url,
            streams=2,
            requests=3,
            clips_s=(1.0,),
            fps=50.0,
            engine="viseme-lerp",
            character="demo",
            pause_s=0.0,
            max_duration_s=30.0,
            workers=2,
            probe_phonemes=5,
        )
        results = loadtest(config)
    clip = results["clips"][0]
    assert clip["requests"] == 3 and clip["successful_requests"] == 3
    assert clip["frames"] == 3 * 51  # frames i with i / 50 <= 1 s, per request
    # both sessions' first requests start within the 1 s stagger and last a 1 s clip, so
    # the two sessions (one in each process) are held at once
    assert clip["peak_sessions"] == 2
    lag = clip["frame_lag_ms"]
    assert math.isfinite(lag["max"]) and lag["p50"] <= lag["p99"] <= lag["max"]
    assert clip["client_cpu_s"] > 0
    probe = clip["probe"]
    assert probe["phonemes"] == 5 and probe["errors"] == {} and probe["requests"] >= 1
    latency = probe["first_frame_latency_ms"]
    # measured from its request's start to its first frame, within the run
    assert 0 < latency["p50"] <= latency["max"] < 1000.0 * clip["wall_s"]
