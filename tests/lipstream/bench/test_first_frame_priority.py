"""The first-frame bench's plan and summary, with the load test stood in (no servers)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

import lipstream.bench.first_frame_priority as bench
from lipstream.bench.report import BLOCKS, Bench
from lipstream.loadtest.load import LoadTestConfig


def fake_results(p99: float) -> dict[str, Any]:
    probe = {"p50": 1.0, "p99": p99, "max": 2 * p99, "min": 0.5}
    return {
        "clips": [
            {
                "probe": {"requests": 7, "errors": {}, "first_frame_latency_ms": probe},
                "frame_lag_ms": {"p50": -3.0, "p99": 12.0, "max": 40.0},
                "peak_sessions": 5,
                "requests": 5,
                "errors": {"server_busy": 1},
            }
        ]
    }


def test_servers_alternate_each_round_after_an_unmeasured_warm_up(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    runs: list[tuple[str | None, str, int]] = []

    def loadtest(config: LoadTestConfig) -> dict[str, Any]:
        runs.append((config.engine, config.url, config.streams))
        return fake_results(10.0 * len(runs))

    monkeypatch.setattr(bench, "loadtest", loadtest)
    monkeypatch.setattr(bench, "PAUSE_S", 0.0)
    out = tmp_path / "ff.json"
    bench.main(
        ["--before", "ws://b", "--after", "ws://a", "--engine", "hmm", "--streams", "5"]
        + ["--results", str(out)]
    )
    assert runs == [
        ("hmm", "ws://b", bench.WARMUP_STREAMS),
        ("hmm", "ws://a", bench.WARMUP_STREAMS),
        ("hmm", "ws://b", 5),
        ("hmm", "ws://a", 5),
        ("hmm", "ws://a", 5),
        ("hmm", "ws://b", 5),
    ]
    written = json.loads(out.read_text(encoding="utf-8"))
    assert [(row["round"], row["side"]) for row in written["rows"]] == [
        (0, "before"),
        (0, "after"),
        (1, "after"),
        (1, "before"),
    ]
    assert [row["first_frame_ms"]["p99"] for row in written["rows"]] == [30.0, 40.0, 50.0, 60.0]
    assert written["command"].startswith("python -m lipstream.bench.first_frame_priority")


def test_a_run_keeps_the_probe_lag_and_admission_figures() -> None:
    summary = bench.run_summary(fake_results(33.0))
    assert summary == {
        "probe_requests": 7,
        "probe_errors": {},
        "first_frame_ms": {"p50": 1.0, "p99": 33.0, "max": 66.0},
        "frame_lag_ms": {"p50": -3.0, "p99": 12.0},
        "peak_sessions": 5,
        "requests": 5,
        "errors": {"server_busy": 1},
    }


def test_the_report_says_for_each_server_whether_its_worst_round_meets_the_target(
    tmp_path: Path,
) -> None:
    rows = []
    for side, p99s in (("before", (20.0, 48.0)), ("after", (30.0, 71.0))):
        for number, p99 in enumerate(p99s):
            summary = bench.run_summary(fake_results(p99))
            rows.append({"engine": "hmm", "round": number, "side": side, **summary})
    doc = {
        "command": "python -m lipstream.bench.first_frame_priority",
        "date": "2026-12-04",
        "machine": {"cores": 2},
        "streams": 500,
        "clip_s": 10.0,
        "probe_phonemes": 30,
        "lead_ms": 0.0,
        "latency_budget_ms": 20.0,
        "target_p99_ms": 50.0,
        "rows": rows,
    }
    (tmp_path / "first_frame_priority.json").write_text(json.dumps(doc), encoding="utf-8")
    rendered = BLOCKS["first-frame-priority"](Bench(tmp_path))
    assert "`hmm`: first frame p99 by round, before 20, 48 ms (met); after 30, 71 ms " in rendered
    assert "(missed by 21 ms)" in rendered
    assert rendered.count("| `hmm` |") == 4
    assert "| `hmm` | before | 2 | 1 / 48 / 96 (7) | -3 / 12 | 5 of 5 | server_busy 1 |" in rendered
