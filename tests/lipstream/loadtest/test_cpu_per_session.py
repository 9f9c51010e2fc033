"""``lipstream loadtest cpu``: legs alternate server and reference, and each side's CPU is
divided by the session-seconds it streamed."""

from __future__ import annotations

import json
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

from lipstream.bench.report import Bench, _against_target, cpu_per_session
from lipstream.engines.base import frame_count
from lipstream.errors import InvalidRequestError, LipstreamError
from lipstream.loadtest.cpu_per_session import (
    CpuComparison,
    check_comparison,
    compare_cpu,
    record_run,
)
from lipstream.loadtest.load import LoadTestConfig
from lipstream.loadtest.reference import ReferenceTraffic, reference_server

SERVER_URL = "ws://127.0.0.1:8000/v1/stream"
REFERENCE_URL = "ws://127.0.0.1:9/v1/stream"
BASE = LoadTestConfig(
    url=SERVER_URL, streams=100, engine="anime-graph", character="demo", latency_budget_ms=20.0
)
TRAFFIC = ReferenceTraffic(("jawOpen", "mouthClose"), 0.0, "causal_lead")
RETURN_FRAMES = 9  # the server's default return to rest after end: 150 ms at 60 fps


def _document(
    config: LoadTestConfig, frames: int, cpu_s: float | None, failed: int = 0, processes: int = 3
) -> dict[str, Any]:
    """A load-test document as ``loadtest`` shapes it, for a fake leg."""
    return {
        "config": {"streams": config.streams, "fps": config.fps},
        "clips": [
            {
                "requests": config.requests,
                "successful_requests": config.requests - failed,
                "errors": {"timeout": failed} if failed else {},
                "peak_sessions": config.streams,
                "frames": frames,
                "server_cpu_s": cpu_s,
                "frame_lag_ms": {"p99": 12.0 if config.url == SERVER_URL else 4.0},
                "wall_s": 21.0,
                "client_cpu_s": 5.0,
            }
        ],
        "summary": {"server_processes": processes},
    }


class FakeLegs:
    """Answers each leg with the next scripted (frames, CPU s, failed) and records its URL."""

    def __init__(self, script: list[tuple[int, float | None, int]]) -> None:
        self.script = script
        self.configs: list[LoadTestConfig] = []
        self.reference_workers: list[int] = []
        self.pauses: list[float] = []

    def run(self, config: LoadTestConfig) -> dict[str, Any]:
        frames, cpu_s, failed = self.script[len(self.configs)]
        self.configs.append(config)
        return _document(config, frames, cpu_s, failed)

    @contextmanager
    def serve(self, traffic: ReferenceTraffic, workers: int) -> Iterator[str]:
        assert traffic == TRAFFIC
        self.reference_workers.append(workers)
        yield REFERENCE_URL

    def compare(self, comparison: CpuComparison) -> dict[str, Any]:
        return compare_cpu(
            comparison,
            run=self.run,
            learn_traffic=lambda base: TRAFFIC,
            serve_reference=self.serve,
            sleep=self.pauses.append,
        )


def test_legs_alternate_and_each_side_divides_its_cpu_by_the_session_seconds_streamed() -> None:
    # 6000 frames at 60 fps are 100 session-seconds per leg.
    legs = FakeLegs([(6000, 0.2, 0), (6000, 0.1, 0), (6000, 0.3, 0), (6000, 0.1, 0)])
    result = legs.compare(CpuComparison(BASE, duration_s=20.0, rounds=2, pause_s=1.5))
    assert [config.url for config in legs.configs] == [SERVER_URL, REFERENCE_URL] * 2
    assert all(config.requests == 100 and config.clips_s == (20.0,) for config in legs.configs)
    assert legs.pauses == [1.5, 1.5, 1.5]
    assert legs.reference_workers == [2]  # a supervisor and two workers found on the port
    assert result["server"]["cpu_ms_per_session_s"] == pytest.approx(500.0 / 200.0)
    assert result["reference"]["cpu_ms_per_session_s"] == pytest.approx(200.0 / 200.0)
    assert result["cpu_ratio"] == pytest.approx(2.5)
    assert result["cpu_ratio_per_round"] == pytest.approx([2.0, 3.0])
    assert result["server"]["frame_lag_ms_p99"] == 12.0
    assert result["reference"]["frame_lag_ms_p99"] == 4.0
    assert result["held"] is True


def test_a_failed_request_marks_the_count_not_held_and_unknown_cpu_gives_no_ratio() -> None:
    legs = FakeLegs([(6000, 0.2, 0), (5940, None, 1)])
    result = legs.compare(CpuComparison(BASE, rounds=1))
    assert result["server"]["held"] is True
    assert result["reference"]["held"] is False and result["held"] is False
    assert result["reference"]["cpu_ms_per_session_s"] is None
    assert result["cpu_ratio"] is None and result["cpu_ratio_per_round"] == [None]


@pytest.mark.parametrize(
    ("comparison", "flag"),
    [
        (CpuComparison(BASE, rounds=0), "--rounds"),
        (CpuComparison(BASE, duration_s=0.5), "--duration"),
        (CpuComparison(BASE, pause_s=-1.0), "--pause"),
        (CpuComparison(LoadTestConfig(url="ws://192.0.2.1:8000/v1/stream")), "--url"),
    ],
)
def test_out_of_bounds_options_are_named(comparison: CpuComparison, flag: str) -> None:
    with pytest.raises(LipstreamError) as raised:
        check_comparison(comparison)
    assert raised.value.where == flag


def test_runs_accumulate_by_key_and_render_into_the_report(tmp_path: Path) -> None:
    path = tmp_path / "bench" / "cpu_per_session.json"
    causal = FakeLegs([(6000, 0.2, 0), (6000, 0.1, 0)]).compare(CpuComparison(BASE, rounds=1))
    record_run(path, causal, "lipstream loadtest cpu --engine anime-graph")
    again = FakeLegs([(6000, 0.4, 0), (6000, 0.1, 0)]).compare(CpuComparison(BASE, rounds=1))
    record_run(path, again, "lipstream loadtest cpu --engine anime-graph")
    other = CpuComparison(LoadTestConfig(url=SERVER_URL, streams=100, engine="hmm"), rounds=1)
    record_run(path, FakeLegs([(6000, 0.3, 0), (6000, 0.2, 0)]).compare(other), "other")
    document = json.loads(path.read_text(encoding="utf-8"))
    assert [run["engine"] for run in document["runs"]] == ["anime-graph", "hmm"]
    assert document["runs"][0]["cpu_ratio"] == pytest.approx(4.0)
    assert document["machine"]["cpus"] >= 1 and document["date"] and document["command"]
    rendered = cpu_per_session(Bench(path.parent))
    assert "| `anime-graph` | `causal_lead` (lead 0 ms, budget 20 ms) | 100, 1 × 20 s |" in rendered
    assert (
        "| 4.000 | 1.000 | **4.00** (4.00) | 12.0 / 4.0 | yes / yes | ≤ 1.25: missed by 3.20× |"
        in rendered
    )
    assert (
        "| 3.000 | 2.000 | **1.50** (1.50) | 12.0 / 4.0 | yes / yes | ≤ 1.25: missed by 1.20× |"
        in rendered
    )


@pytest.mark.parametrize(
    ("fidelity", "ratio", "verdict"),
    [
        ("causal", 1.25, "≤ 1.25: met"),
        ("causal_lead", 2.5, "≤ 1.25: missed by 2.00×"),
        ("lag-4", 1.5, "≤ 1.5: met"),
        ("greedy_tile10", 3.0, "≤ 1.5: missed by 2.00×"),
        ("full", None, "≤ 1.5: not measured"),
    ],
)
def test_each_ratio_is_held_against_its_rungs_target(
    fidelity: str, ratio: float | None, verdict: str
) -> None:
    assert _against_target(fidelity, ratio) == verdict


def test_a_file_of_another_kind_is_not_overwritten(tmp_path: Path) -> None:
    path = tmp_path / "capacity.json"
    path.write_text('{"searches": []}', encoding="utf-8")
    result = FakeLegs([(6000, 0.2, 0), (6000, 0.1, 0)]).compare(CpuComparison(BASE, rounds=1))
    with pytest.raises(LipstreamError) as raised:
        record_run(path, result, "command")
    assert raised.value.code == "invalid_results_file"
    assert path.read_text(encoding="utf-8") == '{"searches": []}'


def test_a_short_real_run_measures_both_servers_cpu_over_the_frames_streamed() -> None:
    # A reference server stands in for the measured one: it runs in processes of its own
    # (a supervisor and two workers) and streams as an engine would, with no training. It
    # ignores cancel, so the traffic is given rather than learnt from a cancelled request.
    streams, duration_s, fps = 3, 2.0, 60.0
    with reference_server(TRAFFIC, workers=2) as measured_url:
        config = LoadTestConfig(
            url=measured_url, streams=streams, engine="anime-graph", character="demo", fps=fps
        )
        progress: list[str] = []
        result = compare_cpu(
            CpuComparison(config, duration_s=duration_s, rounds=1, pause_s=0.0),
            progress=progress.append,
            learn_traffic=lambda base: TRAFFIC,
        )
    assert [leg["side"] for leg in result["legs"]] == ["server", "reference"]
    assert tuple(result["reference"]["traffic"]["channels"]) == TRAFFIC.channels
    assert result["reference"]["workers"] == 2
    expected_session_s = streams * (frame_count(duration_s, fps) + RETURN_FRAMES) / fps
    for side in ("server", "reference"):
        figures = result[side]
        assert figures["server_processes"] == 3
        assert figures["held"] is True
        assert figures["session_s"] == pytest.approx(expected_session_s)
        assert figures["server_cpu_s"] is not None and figures["server_cpu_s"] >= 0.0
        assert figures["cpu_ms_per_session_s"] is not None
    assert len(progress) == 2


def test_the_command_refuses_a_foreign_results_file_before_measuring(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from lipstream.cli import main

    foreign = tmp_path / "other.json"
    foreign.write_text("[1, 2]", encoding="utf-8")
    assert (
        main(
            [
                "loadtest",
                "cpu",
                "--engine",
                "anime-graph",
                "--character",
                "demo",
                "--url",
                REFERENCE_URL,
                "--results",
                str(foreign),
            ]
        )
        == 2
    )
    assert "error [invalid_results_file]" in capsys.readouterr().err
    assert foreign.read_text(encoding="utf-8") == "[1, 2]"


def test_rounds_are_bounded() -> None:
    with pytest.raises(InvalidRequestError):
        check_comparison(CpuComparison(BASE, rounds=11))
