"""The server's own CPU per session-second, beside the reference server's, in one run.

Sketch: a session count on a small machine also measures the load generator,
which shares the cores, so this run compares what the servers themselves
spend. One leg is a ``lipstream loadtest`` run in which ``streams`` sessions
each stream one clip of ``duration_s`` seconds at the requested fps (all of
them connect within the first second, as in the load test). The legs
alternate between the measured server (A) and the reference server (B: the
same messages at the same rate, no synthesis; see ``reference``): A B A B
... for ``rounds`` rounds, so a neighbour's load on a shared machine falls
on both sides alike. Each leg reads the CPU time of the server's processes
from ``/proc`` (``cpu``), before and after. A side's figure is its CPU
milliseconds over the session-seconds it streamed (frames received / fps),
summed over its legs; the ratio is A's figure over B's. Beside them: each
side's worst p99 frame lag and whether every leg held its count (every
request succeeded and all sessions were streaming at once at some instant).

Runs accumulate in one results file (``--results``, by default
``$LIPSTREAM_HOME/bench/cpu_per_session.json``): a run replaces the one with
the same engine, character, fps, lead, budget, encoding, sessions and length.

Usage (the server already running on this machine)::

    lipstream loadtest cpu --engine anime-graph --character demo \\
        --latency-budget-ms 20 --streams 150 --duration 20 --rounds 2
"""

from __future__ import annotations

import datetime
import os
import platform
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

from .._version import __version__
from ..errors import InvalidRequestError
from ..results_file import read_accumulated, write_results
from .capacity import LearnTraffic, Progress, ServeReference, reference_workers, traffic_of
from .load import LoadTestConfig, check_config, loadtest
from .reference import reference_server
from .sessions import event_loop_name

MAX_ROUNDS = 10
MAX_DURATION_S = 60.0
RESULTS_NAME = "cpu_per_session.json"
_RUN_KEY = (
    "engine",
    "character",
    "fps",
    "lead_ms",
    "latency_budget_ms",
    "encoding",
    "streams",
    "duration_s",
)

Run = Callable[[LoadTestConfig], dict[str, Any]]
Sleep = Callable[[float], None]


@dataclass(frozen=True)
class CpuComparison:
    """``base`` names the target and the session count (``streams``); each leg streams one
    clip of ``duration_s`` seconds per session; ``rounds`` pairs of legs (A then B), with
    ``pause_s`` seconds between legs (the servers' clean-up time)."""

    base: LoadTestConfig
    duration_s: float = 20.0
    rounds: int = 2
    pause_s: float = 2.0


def leg_config(comparison: CpuComparison, url: str) -> LoadTestConfig:
    """The load test of one leg against ``url``: one request per session."""
    base = comparison.base
    return replace(
        base,
        url=url,
        requests=base.streams,
        clips_s=(comparison.duration_s,),
        pause_s=0.0,
    )


def check_comparison(comparison: CpuComparison) -> None:
    """InvalidRequestError naming the flag whose value is out of bounds."""
    bounds: list[tuple[str, bool, str]] = [
        (
            "--duration",
            1.0 <= comparison.duration_s <= MAX_DURATION_S,
            f"[1, {MAX_DURATION_S:g}] s",
        ),
        ("--rounds", 1 <= comparison.rounds <= MAX_ROUNDS, f"1..{MAX_ROUNDS}"),
        ("--pause", 0 <= comparison.pause_s <= 60, "[0, 60] s"),
    ]
    for flag, ok, allowed in bounds:
        if not ok:
            raise InvalidRequestError(f"must be {allowed}", where=flag)
    check_config(leg_config(comparison, comparison.base.url))


def leg_summary(side: str, results: dict[str, Any]) -> dict[str, Any]:
    """The figures of one leg: CPU, session-seconds streamed, lag, and whether it held."""
    clip = results["clips"][0]
    streams = results["config"]["streams"]
    fps = results["config"]["fps"]
    session_s = clip["frames"] / fps
    cpu_s = clip["server_cpu_s"]
    return {
        "side": side,
        "server_processes": results["summary"]["server_processes"],
        "held": clip["successful_requests"] == clip["requests"]
        and clip["peak_sessions"] >= streams,
        "successful_requests": clip["successful_requests"],
        "requests": clip["requests"],
        "errors": clip["errors"],
        "peak_sessions": clip["peak_sessions"],
        "frames": clip["frames"],
        "session_s": session_s,
        "server_cpu_s": cpu_s,
        "cpu_ms_per_session_s": None
        if cpu_s is None or session_s <= 0
        else 1000.0 * cpu_s / session_s,
        "frame_lag_ms_p99": clip["frame_lag_ms"]["p99"],
        "wall_s": clip["wall_s"],
        "client_cpu_s": clip["client_cpu_s"],
    }


def side_summary(legs: list[dict[str, Any]]) -> dict[str, Any]:
    """One side's legs together: CPU over session-seconds summed over its legs."""
    cpu = [leg["server_cpu_s"] for leg in legs]
    session_s = sum(leg["session_s"] for leg in legs)
    known = None not in cpu and session_s > 0
    lags = [leg["frame_lag_ms_p99"] for leg in legs if leg["frame_lag_ms_p99"] is not None]
    return {
        "legs": len(legs),
        "server_processes": legs[0]["server_processes"],
        "server_cpu_s": sum(c for c in cpu if c is not None) if known else None,
        "session_s": session_s,
        "cpu_ms_per_session_s": 1000.0 * sum(c for c in cpu if c is not None) / session_s
        if known
        else None,
        "frame_lag_ms_p99": max(lags, default=None),
        "held": all(leg["held"] for leg in legs),
    }


def _ratio(numerator: float | None, denominator: float | None) -> float | None:
    if numerator is None or not denominator:
        return None
    return numerator / denominator


def compare_cpu(
    comparison: CpuComparison,
    run: Run = loadtest,
    progress: Progress | None = None,
    learn_traffic: LearnTraffic = traffic_of,
    serve_reference: ServeReference = reference_server,
    sleep: Sleep = time.sleep,
) -> dict[str, Any]:
    """Run the legs A B A B ... and return the run's document (see
    docs/how-to/load-testing.md, "CPU per session-second")."""
    check_comparison(comparison)
    base = comparison.base
    traffic = learn_traffic(base)
    legs: list[dict[str, Any]] = []

    def leg(side: str, url: str) -> None:
        if legs:
            sleep(comparison.pause_s)
        summary = leg_summary(side, run(leg_config(comparison, url)))
        legs.append(summary)
        if progress is not None:
            progress(_leg_line(summary))

    leg("server", base.url)
    workers = reference_workers(legs[0]["server_processes"])
    with serve_reference(traffic, workers) as reference_url:
        for number in range(comparison.rounds):
            if number:
                leg("server", base.url)
            leg("reference", reference_url)
    server = side_summary([one for one in legs if one["side"] == "server"])
    reference = side_summary([one for one in legs if one["side"] == "reference"])
    rounds = [
        _ratio(a["cpu_ms_per_session_s"], b["cpu_ms_per_session_s"])
        for a, b in zip(legs[0::2], legs[1::2], strict=True)
    ]
    return {
        "engine": base.engine,
        "character": base.character,
        "fps": base.fps,
        "lead_ms": base.lead_ms,
        "latency_budget_ms": base.latency_budget_ms,
        "fidelity": traffic.fidelity,
        "encoding": base.encoding,
        "streams": base.streams,
        "duration_s": comparison.duration_s,
        "rounds": comparison.rounds,
        "server": server,
        "reference": {**reference, "traffic": asdict(traffic), "workers": workers},
        "cpu_ratio": _ratio(server["cpu_ms_per_session_s"], reference["cpu_ms_per_session_s"]),
        "cpu_ratio_per_round": rounds,
        "held": server["held"] and reference["held"],
        "legs": legs,
        "config": {**asdict(base), "token": None},
    }


def _leg_line(leg: dict[str, Any]) -> str:
    cost = leg["cpu_ms_per_session_s"]
    lag = leg["frame_lag_ms_p99"]
    return (
        f"{leg['side']:>9}: {leg['peak_sessions']} at once, "
        f"{leg['successful_requests']}/{leg['requests']} ok, "
        f"{'-' if cost is None else f'{cost:.3f}'} CPU ms per session-second, "
        f"lag p99 {'-' if lag is None else f'{lag:.1f}'} ms"
        + ("" if leg["held"] else "  (count NOT held)")
    )


def comparison_line(result: dict[str, Any]) -> str:
    """One line: both sides' figures and their ratio."""
    server, reference, ratio = result["server"], result["reference"], result["cpu_ratio"]

    def cost(side: dict[str, Any]) -> str:
        value = side["cpu_ms_per_session_s"]
        return "-" if value is None else f"{value:.3f}"

    return (
        f"{result['engine']} ({result['fidelity']}), {result['streams']} sessions: server "
        f"{cost(server)} CPU ms per session-second, reference {cost(reference)}, ratio "
        f"{'-' if ratio is None else f'{ratio:.2f}'}; "
        + ("count held" if result["held"] else "count NOT held")
    )


def read_results(path: Path) -> dict[str, Any]:
    """The CPU-per-session results file at ``path`` (``results_file.read_accumulated``)."""
    return read_accumulated(path, "runs", "CPU-per-session")


def record_run(path: Path, result: dict[str, Any], command: str) -> None:
    """Add ``result`` to the results file at ``path``, replacing a run with the same key;
    the run keeps its date and ``command``."""
    document = read_results(path)
    date = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
    entry = {**result, "date": date, "command": command}
    key = tuple(entry.get(name) for name in _RUN_KEY)
    kept = [old for old in document["runs"] if tuple(old.get(name) for name in _RUN_KEY) != key]
    write_results(
        {
            "tool": f"lipstream loadtest cpu {__version__}",
            "machine": {
                "cpus": os.cpu_count(),
                "platform": platform.platform(),
                "python": platform.python_version(),
                "event_loop": event_loop_name(),
            },
            "date": date,
            "command": command,
            "runs": [*kept, entry],
        },
        path,
    )
