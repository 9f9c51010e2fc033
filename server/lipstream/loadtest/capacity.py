"""How many concurrent real-time sessions a server holds: a search over load-test runs.

Sketch: one probe is a ``lipstream loadtest`` run with N sessions, each
streaming ``REQUESTS_PER_SESSION`` utterances of one clip length one after
another on its connection, as a game client speaks line after line (all N
connect within the first second). A probe passes when every request
succeeds, all N sessions were held at once at some instant (``peak_sessions``:
each session from its first request's ``ready`` to its last one's ``done``),
and the p99 frame lag, measured against each frame's scheduled time, is
under ``lag_limit_ms``. The server's admission may refuse part of a burst of
connections for a second or two (``server_busy``; the sessions wait the time
they were given and try again): the second utterance keeps the first
sessions streaming while the last get in, so a count passes on what the
server holds, not on how fast it admits. The search doubles N from ``start`` until
a probe fails (or ``max_streams`` passes), then bisects between the last
pass and the first failure down to ``resolution`` sessions. Lag rises
steeply once the cores saturate, so the boundary is sharp and a handful of
probes find it. Before the search one idle probe (one session) measures the
baseline: the lag that the engine's lookahead and the chosen lead leave
with no load, and the idle first-frame latency. Each probe records the load
generator's and the server's CPU seconds, so a reader can tell which side
ran out of CPU.

Searches accumulate in one results file (``--results``, by default
``$LIPSTREAM_HOME/bench/capacity.json``): a new search replaces the one with
the same engine, character, fps, lead and clip.

Capacity as a ratio: an absolute count says as much about the machine as
about the code, so the same run also searches the capacity of the
reference server (``reference``: the same messages at the same rate, no
synthesis), started with as many workers as the measured server has, and
reports the engine's count over the reference's (``capacity_ratio``). Runs
for several engines (``--engine all``) share one reference search per
distinct traffic (channels, lookahead, rung).

Usage (the server already running on this machine)::

    lipstream loadtest capacity --engine viseme-lerp --character demo \\
        --lead-ms 300 --workers 2 --probe-phonemes 30
"""

from __future__ import annotations

import time
from collections.abc import Callable
from contextlib import AbstractContextManager
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

from .._version import __version__
from ..errors import InvalidRequestError
from ..results_file import machine, read_accumulated, write_results
from .load import LoadTestConfig, check_config, loadtest
from .reference import ReferenceTraffic, engine_traffic, reference_server
from .sessions import event_loop_name

REQUESTS_PER_SESSION = 2
MAX_PROBES = 24
_SEARCH_KEY = (
    "engine",
    "character",
    "fps",
    "lead_ms",
    "latency_budget_ms",
    "clip_s",
    "encoding",
    "server_processes",
)


@dataclass(frozen=True)
class CapacitySearch:
    """The search: ``base`` gives everything but the session count; probes use one clip
    of ``clip_s`` seconds and one request per session."""

    base: LoadTestConfig
    clip_s: float = 10.0
    lag_limit_ms: float = 50.0
    start: int = 100
    max_streams: int = 1000
    resolution: int = 25
    pause_s: float = 3.0
    reference: bool = True


def check_search(search: CapacitySearch) -> None:
    """InvalidRequestError naming the flag whose value is out of bounds."""
    bounds: list[tuple[str, bool, str]] = [
        ("--lag-limit-ms", 0 < search.lag_limit_ms <= 10_000, "(0, 10000]"),
        ("--start", 1 <= search.start <= search.max_streams, "1..--max-streams"),
        ("--resolution", 1 <= search.resolution <= search.max_streams, "1..--max-streams"),
        ("--pause", 0 <= search.pause_s <= 60, "[0, 60] s"),
    ]
    for flag, ok, allowed in bounds:
        if not ok:
            raise InvalidRequestError(f"must be {allowed}", where=flag)
    check_config(probe_config(search, search.max_streams))


def probe_config(search: CapacitySearch, streams: int) -> LoadTestConfig:
    """The load test of one probe with ``streams`` sessions."""
    return replace(
        search.base,
        streams=streams,
        requests=REQUESTS_PER_SESSION * streams,
        clips_s=(search.clip_s,),
        pause_s=0.0,
        workers=min(search.base.workers, streams),
    )


def probe_summary(streams: int, results: dict[str, Any], lag_limit_ms: float) -> dict[str, Any]:
    """The figures of one probe that decide it and explain it."""
    clip = results["clips"][0]
    lag = clip["frame_lag_ms"]
    wall = clip["wall_s"]
    passed = (
        clip["successful_requests"] == clip["requests"]
        and clip["peak_sessions"] >= streams
        and lag["p99"] is not None
        and lag["p99"] < lag_limit_ms
    )
    probe = clip["probe"]
    return {
        "streams": streams,
        "server_processes": results["summary"]["server_processes"],
        "passed": passed,
        "successful_requests": clip["successful_requests"],
        "requests": clip["requests"],
        "errors": clip["errors"],
        "peak_sessions": clip["peak_sessions"],
        "busy_retries": clip["busy_retries"],
        "frame_lag_ms": lag,
        "first_packet_latency_ms": {
            key: clip["first_packet_latency_ms"][key] for key in ("p50", "p99", "max")
        },
        "fps_p1": clip["fps"]["p1"],
        "send_slip_ms_p99": clip["send_slip_ms"]["p99"],
        "probe_first_frame_latency_ms": None
        if probe is None
        else {key: probe["first_frame_latency_ms"][key] for key in ("p50", "p99", "max")},
        "probe_requests": None if probe is None else probe["requests"],
        "wall_s": wall,
        "client_cpu_s": clip["client_cpu_s"],
        "server_cpu_s": clip["server_cpu_s"],
        "client_cores": clip["client_cpu_s"] / wall if wall else None,
        "server_cores": None
        if clip["server_cpu_s"] is None or not wall
        else clip["server_cpu_s"] / wall,
    }


def next_probe(passed: dict[int, bool], search: CapacitySearch) -> int | None:
    """The next session count to try given the verdicts so far, or None when done."""
    if not passed:
        return search.start
    good = [n for n, ok in passed.items() if ok]
    bad = [n for n, ok in passed.items() if not ok]
    low = max(good, default=0)
    high = min((n for n in bad if n > low), default=None)
    if high is None:
        if low >= search.max_streams:
            return None
        return min(2 * low, search.max_streams)
    if high - low <= search.resolution:
        return None
    middle = (low + high) // 2
    return (
        max(low + 1, middle - middle % search.resolution) if middle > search.resolution else middle
    )


Run = Callable[[LoadTestConfig], dict[str, Any]]
Progress = Callable[[str], None]
ServeReference = Callable[[ReferenceTraffic, int], AbstractContextManager[str]]
LearnTraffic = Callable[[LoadTestConfig], ReferenceTraffic]
_REFERENCE_FIELDS = ("capacity_streams", "upper_bound_streams", "idle", "at_capacity", "probes")


def traffic_of(base: LoadTestConfig) -> ReferenceTraffic:
    """The traffic the measured engine sends for the search's requests (one ``ready``)."""
    if base.engine is None or base.character is None:
        raise InvalidRequestError("a capacity search names its engine", where="--engine")
    return engine_traffic(
        base.url,
        base.engine,
        base.character,
        base.fps,
        base.latency_budget_ms,
        base.token,
        base.encoding,
    )


def reference_workers(server_processes: int) -> int:
    """uvicorn workers matching a server found as ``server_processes`` listening processes
    (a supervisor and its workers, or one process)."""
    return server_processes - 1 if server_processes > 1 else 1


def find_capacity(
    search: CapacitySearch,
    run: Run = loadtest,
    progress: Progress | None = None,
    learn_traffic: LearnTraffic = traffic_of,
    serve_reference: ServeReference = reference_server,
    references: dict[tuple[ReferenceTraffic, int], dict[str, Any]] | None = None,
) -> dict[str, Any]:
    """Run the search, then the reference's unless ``search.reference`` is off (or an
    equal one is in ``references``, which collects them); the document (see
    docs/how-to/load-testing.md, "Capacity")."""
    check_search(search)
    document = search_sessions(search, run, progress)
    if not search.reference:
        return document
    traffic = learn_traffic(search.base)
    workers = reference_workers(document["server_processes"])
    known = {} if references is None else references
    if (traffic, workers) not in known:
        if progress is not None:
            progress(f"reference server ({workers} worker(s), {len(traffic.channels)} channels)")
        with serve_reference(traffic, workers) as url:
            measured = search_sessions(
                replace(search, base=replace(search.base, url=url)), run, progress
            )
        known[(traffic, workers)] = {
            "traffic": asdict(traffic),
            "workers": workers,
            **{name: measured[name] for name in _REFERENCE_FIELDS},
        }
    reference = known[(traffic, workers)]
    document["reference"] = reference
    document["capacity_ratio"] = (
        document["capacity_streams"] / reference["capacity_streams"]
        if reference["capacity_streams"]
        else None
    )
    return document


def search_sessions(search: CapacitySearch, run: Run, progress: Progress | None) -> dict[str, Any]:
    """The session-count search on ``search.base.url`` alone."""
    passed: dict[int, bool] = {}
    probes: list[dict[str, Any]] = []
    began = time.perf_counter()
    idle = probe_summary(1, run(probe_config(search, 1)), search.lag_limit_ms)
    if progress is not None:
        progress(_probe_line(idle) + "  (idle baseline)")
    while (streams := next_probe(passed, search)) is not None and len(probes) < MAX_PROBES:
        time.sleep(search.pause_s)
        summary = probe_summary(streams, run(probe_config(search, streams)), search.lag_limit_ms)
        passed[streams] = summary["passed"]
        probes.append(summary)
        if progress is not None:
            progress(_probe_line(summary))
    capacity = max((n for n, ok in passed.items() if ok), default=0)
    base = search.base
    return {
        "engine": base.engine,
        "character": base.character,
        "fps": base.fps,
        "lead_ms": base.lead_ms,
        "latency_budget_ms": base.latency_budget_ms,
        "clip_s": search.clip_s,
        "encoding": base.encoding,
        "workers": base.workers,
        "server_processes": idle["server_processes"],
        "lag_limit_ms": search.lag_limit_ms,
        "criterion": f"every request succeeds ({REQUESTS_PER_SESSION} per session, one after "
        f"another), all sessions are held at once at some instant (peak_sessions: first "
        f"ready to last done), and p99 frame lag < {search.lag_limit_ms:g} ms "
        f"(lag: arrival minus scheduled time, start sent + i / fps)",
        "capacity_streams": capacity,
        "upper_bound_streams": min(
            (n for n, ok in passed.items() if not ok and n > capacity), default=None
        ),
        "idle": idle,
        "at_capacity": next((p for p in probes if p["streams"] == capacity), None),
        "probes": probes,
        "search_s": time.perf_counter() - began,
        "config": {**asdict(base), "token": None},
    }


def _probe_line(probe: dict[str, Any]) -> str:
    lag = probe["frame_lag_ms"]
    server = probe["server_cores"]
    return (
        f"{probe['streams']:>5} sessions: {'pass' if probe['passed'] else 'FAIL'}  "
        f"{probe['successful_requests']}/{probe['requests']} ok, "
        f"{probe['peak_sessions']} at once, lag p99 "
        f"{_number(lag['p99'])} ms, max {_number(lag['max'])} ms; cores used: client "
        f"{_number(probe['client_cores'], 2)}, server {_number(server, 2)}"
    )


def _number(value: float | None, digits: int = 1) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def read_results(path: Path) -> dict[str, Any]:
    """The capacity results file at ``path`` (``results_file.read_accumulated``)."""
    return read_accumulated(path, "searches", "capacity")


def merge_results(path: Path, search: dict[str, Any]) -> dict[str, Any]:
    """The results file with ``search`` added, replacing a search with the same key. The
    file's ``date`` spans its searches' dates and its ``command`` is theirs when they share
    one; its notes (keys holding ``note``) are kept."""
    document = read_results(path)
    key = tuple(search.get(name) for name in _SEARCH_KEY)
    kept = [
        old for old in document["searches"] if tuple(old.get(name) for name in _SEARCH_KEY) != key
    ]
    searches = [*kept, search]
    merged: dict[str, Any] = {
        "tool": f"lipstream loadtest capacity {__version__}",
        "machine": {**machine(), "event_loop": event_loop_name()},
    }
    dates = sorted(str(found["date"]) for found in searches if found.get("date"))
    if dates:
        merged["date"] = dates[0] if dates[0] == dates[-1] else f"{dates[0]} to {dates[-1]}"
    commands = {found.get("command") for found in searches}
    if len(commands) == 1 and None not in commands:
        merged["command"] = commands.pop()
    notes = {name: value for name, value in document.items() if "note" in name}
    return {**merged, **notes, "searches": searches}


def record_search(path: Path, search: dict[str, Any]) -> None:
    """Merge ``search`` into the results file at ``path`` (see ``merge_results``)."""
    write_results(merge_results(path, search), path)
