"""``lipstream loadtest``: statistics, clips, the loopback guard and bounds, a short run."""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
from pathlib import Path

import numpy as np
import pytest

from lipstream.errors import InvalidRequestError
from lipstream.loadtest.clips import synthetic_clip
from lipstream.loadtest.load import (
    LoadTestConfig,
    NotLoopbackError,
    check_config,
    check_loopback,
    format_table,
    http_base,
    loadtest,
    planned_duration_s,
)
from lipstream.loadtest.stats import Summary, overall_summary, percentile, summarize
from lipstream.phonemes import PHONEMES
from lipstream.results_file import write_results
from tests.helpers import run_cli
from tests.lipstream_client.fake_server import FakeServer


def test_percentiles_of_known_latencies() -> None:
    latencies = [50.0, 10.0, 40.0, 20.0, 30.0]
    summary = summarize(latencies)
    # Rank q/100 * (n - 1) over 10, 20, 30, 40, 50; by hand:
    assert summary["min"] == 10.0 and summary["max"] == 50.0
    assert summary["p50"] == 30.0 and summary["mean"] == 30.0
    assert summary["p1"] == pytest.approx(10.4)  # rank 0.04
    assert summary["p5"] == pytest.approx(12.0)  # rank 0.2
    assert summary["p10"] == pytest.approx(14.0)  # rank 0.4
    assert summary["p90"] == pytest.approx(46.0)  # rank 3.6
    assert summary["p95"] == pytest.approx(48.0)  # rank 3.8
    assert summary["p99"] == pytest.approx(49.6)  # rank 3.96


def test_percentile_matches_numpy_default() -> None:
    values = sorted(np.random.default_rng(3).exponential(20.0, size=101).tolist())
    for q in (0, 1, 5, 10, 33.3, 50, 90, 95, 99, 100):
        assert percentile(values, q) == pytest.approx(float(np.percentile(values, q)), rel=1e-12)
    assert percentile([7.0], 99) == 7.0
    with pytest.raises(ValueError):
        percentile([], 50)


def test_empty_sample_gives_nulls_and_overall_summary_follows_a2f() -> None:
    assert set(summarize([]).values()) == {None}
    clips: list[dict[str, Summary]] = [
        {
            "first_packet_latency_ms": {"p99": 12.0, "mean": 4.0},
            "fps": {"p1": 58.0},
            "frame_lag_ms": {"p99": 9.0, "max": 20.0},
        },
        {
            "first_packet_latency_ms": {"p99": 30.0, "mean": 8.0},
            "fps": {"p1": 55.5},
            "frame_lag_ms": {"p99": 7.0, "max": 31.0},
        },
        {
            "first_packet_latency_ms": {"p99": None, "mean": None},
            "fps": {"p1": None},
            "frame_lag_ms": {"p99": None, "max": None},
        },
    ]
    assert overall_summary(clips) == {
        "worst_p99_first_packet_latency_ms": 30.0,
        "mean_first_packet_latency_ms": 6.0,
        "lowest_p1_fps": 55.5,
        "worst_p99_frame_lag_ms": 9.0,
        "max_frame_lag_ms": 31.0,
    }


@pytest.mark.parametrize("length", [5.0, 10.0, 20.0, 1.0])
def test_synthetic_clips_are_contiguous_speech_of_the_exact_length(length: float) -> None:
    spans = synthetic_clip(length, seed=4)
    assert spans == synthetic_clip(length, seed=4)
    assert spans != synthetic_clip(length, seed=5)
    assert spans[0][1] == 0.0 and spans[-1][2] == length
    for (_, _, end), (_, start, _) in itertools.pairwise(spans):
        assert start == end
    assert all(end > start for _, start, end in spans)
    assert {label for label, _, _ in spans} <= set(PHONEMES)
    rate = sum(label != "sil" for label, _, _ in spans) / length
    assert 5.0 < rate < 16.0  # phonemes per second of conversational speech


@pytest.mark.parametrize(
    "url",
    [
        "ws://127.0.0.1:8000/v1/stream",
        "ws://127.9.9.9:1/v1/stream",
        "ws://localhost/v1/stream",
        "ws://[::1]:8000/v1/stream",
        "wss://127.0.0.1/v1/stream",
    ],
)
def test_loopback_targets_are_accepted(url: str) -> None:
    check_loopback(url)


@pytest.mark.parametrize(
    "url",
    [
        "ws://10.0.0.5:8000/v1/stream",
        "ws://example.com/v1/stream",
        "ws://0.0.0.0:8000/v1/stream",
        "ws://[::ffff:8.8.8.8]/v1/stream",
        "http://127.0.0.1:8000/v1/stream",
        "ws://localhost.example.com/v1/stream",
        "ws://127.0.0.1.nip.io/v1/stream",
    ],
)
def test_other_targets_are_refused(url: str) -> None:
    with pytest.raises(NotLoopbackError) as refused:
        check_loopback(url)
    assert refused.value.code == "not_loopback" and refused.value.where == "--url"


@pytest.mark.parametrize(
    ("change", "flag"),
    [
        ({"streams": 0}, "--streams"),
        ({"streams": 2001}, "--streams"),
        ({"requests": 20_001}, "--requests"),
        ({"clips_s": (5.0, 61.0)}, "--clips"),
        ({"clips_s": ()}, "--clips"),
        ({"fps": 0.0}, "--fps"),
        ({"fps": 0.5}, "--fps"),
        ({"max_duration_s": 4000.0}, "--max-duration"),
        ({"streams": 1, "requests": 100}, "--max-duration"),
    ],
)
def test_counts_and_duration_are_bounded(change: dict[str, object], flag: str) -> None:
    config = dataclasses.replace(LoadTestConfig(), **change)  # type: ignore[arg-type]  # bad values on purpose
    with pytest.raises(InvalidRequestError) as refused:
        check_config(config)
    assert refused.value.where == flag


def test_planned_duration_counts_rounds_delays_and_pauses() -> None:
    config = LoadTestConfig(streams=10, requests=25, clips_s=(5.0, 10.0), pause_s=3.0)
    # 3 rounds of (1 s delay + clip) per clip length, one pause between them.
    assert planned_duration_s(config) == 3 * 6.0 + 3 * 11.0 + 3.0
    assert http_base("ws://127.0.0.1:9/v1/stream") == "http://127.0.0.1:9"
    assert http_base("wss://[::1]:9/v1/stream?x=1") == "https://[::1]:9"


def test_a_short_run_measures_every_request(tmp_path: Path) -> None:
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
        )
        results = loadtest(config)
    clip = results["clips"][0]
    assert clip["requests"] == 3 and clip["successful_requests"] == 3 and clip["errors"] == {}
    # The fake server sends frames i with i / fps <= 1 s: 51 per request.
    assert clip["frames"] == 3 * 51
    # Each request's ``ready`` comes before its first frames, so every order statistic of the
    # first-packet latency is at most the first-frame latency's. (Speeds: bench/loadtest.json.)
    first_packet, first_frame = clip["first_packet_latency_ms"], clip["first_frame_latency_ms"]
    assert 0 < first_packet["min"]
    assert all(first_packet[name] <= first_frame[name] for name in results["statistics"])
    lag = clip["frame_lag_ms"]
    assert lag["p50"] <= lag["p95"] <= lag["p99"] <= lag["max"]
    assert 0 < clip["fps"]["min"] <= clip["fps"]["max"]
    assert results["summary"]["requests"] == 3 and results["config"]["token"] is None
    assert set(results["statistics"]) == set(clip["fps"])
    write_results(results, tmp_path / "bench" / "loadtest.json")
    assert (
        json.loads((tmp_path / "bench" / "loadtest.json").read_text())["clips"][0]["frames"] == 153
    )
    table = format_table(results)
    assert "3/3" in table and "worst p99 first-packet latency" in table
    assert math.isfinite(results["summary"]["wall_s"])


def test_cli_refuses_a_remote_target_with_one_line(tmp_path: Path) -> None:
    result = run_cli(
        "loadtest",
        "--url",
        "ws://192.0.2.1:8000/v1/stream",
        "--results",
        str(tmp_path / "out.json"),
    )
    assert result.returncode == 2
    assert result.stderr.startswith("error [not_loopback]: --url: ")
    assert not (tmp_path / "out.json").exists()


def test_a_start_refused_for_load_is_retried_on_the_same_connection() -> None:
    # The server turns the first two starts away with a request-scope server_busy (its
    # engine costs more than the load leaves room for); the session waits retry_after_ms
    # and starts again without reconnecting.
    with FakeServer(busy_starts=2) as server:
        config = LoadTestConfig(
            url=server.url,
            streams=1,
            requests=2,
            clips_s=(1.0,),
            fps=50.0,
            engine="viseme-lerp",
            character="demo",
            pause_s=0.0,
            max_duration_s=30.0,
        )
        clip = loadtest(config)["clips"][0]
        connections = len(server.headers)
    assert clip["successful_requests"] == 2 and clip["errors"] == {}
    assert clip["busy_retries"] == 2
    assert connections == 1
