"""A connection storm against a running server: do admission and the health probes hold?

Sketch: ``storm`` first opens ``baseline`` sessions and lets them stream for
``BASELINE_LEAD_S``, then opens ``connections`` connections at once, all of one ``kind``:
``silent`` TCP sockets that never send a byte, ``partial`` ones that send half a request
head and stop, or ``sessions``: WebSockets that each start a request and stream one phoneme
every ``PHONEME_S`` (real time) for ``duration_s``, then end it (the baseline sessions
stream on through the storm). The storm's connections are shared among ``processes`` client
processes (this one and ``processes - 1`` spawned ones, released together once all have
started; with baseline sessions, ``processes`` spawned ones, so that this one's loop, which
stamps the baseline sessions' frames, is not stalled by the storm's own connections), so
that beyond a few hundred sessions the client is not what limits the figures.
Meanwhile a probe process of its own asks each ``/healthz``
given (the serving port's, and the liveness port's) every ``PROBE_EVERY_S`` with a
``PROBE_TIMEOUT_S`` timeout, and samples the server's resident memory every
``RSS_EVERY_S``: from ``/proc`` (the process and its children) with ``server_pid``, else
``lipstream_resident_memory_bytes`` from ``/metrics``.

The frame lag is measured on the client's clock, not the server's: each session stamps the
moment it sends each phonemes message, and a reader task stamps each frames block's
arrival; a block's lag is its arrival minus the send of the message covering its first
frame (phoneme ``floor(t / PHONEME_S)`` for a frame at ``t`` s; ``end`` for frames past the
last). With a latency budget at the floor (20 ms) the rung has no lookahead, so all of that
is the server's queueing and work, the network's, and the client's own delay in reading:
the report gives the client's event-loop lag too (``client_loop_lag_ms``, a timer every
``CLIENT_TICK_S``, in every client process), and when it is high the lag figures are the
client's: give more processes. The server's own frame-lag histogram
(``lipstream_frame_lag_seconds``, as bucket bounds) is reported beside it.

The report counts how the connections ended (admitted and finished, refused with
``server_busy`` by ``details.reason``, other errors by code, upgrade refused with HTTP 503,
closed by the server before their head, other failures), the refusals by reason, each
probe's latency percentiles and failures, and the peak resident memory against the
server's memory ceiling (``lipstream_memory_ceiling_bytes``).

    lipstream loadtest storm --url ws://127.0.0.1:8000/v1/stream --kind sessions -n 1100 \\
        --baseline 8 --latency-budget-ms 20 --health-url http://127.0.0.1:8081/healthz \\
        --processes 4
"""

from __future__ import annotations

import asyncio
import json
import math
import multiprocessing
import os
import shlex
import threading
import time
import urllib.request
from collections import Counter
from dataclasses import asdict, dataclass, field
from datetime import UTC, datetime
from multiprocessing.connection import Connection
from multiprocessing.synchronize import Event as EventType
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from lipstream_client import (
    AsyncClient,
    HandshakeRejected,
    LipstreamClientError,
    LipstreamServerError,
    ServerBusy,
)
from lipstream_client.client import Stream

from .._version import __version__
from ..results_file import machine, write_results
from .stats import LAG_STATISTICS, Summary, summarize

PHONEME_S = 0.08
PHONEMES = ("HH", "AH0", "L", "OW1", "W", "ER1", "L", "D", "sil")
PROBE_EVERY_S = 0.5
PROBE_TIMEOUT_S = 1.0
PROBE_START_S = 30.0  # a spawned process imports the standard library first
RSS_EVERY_S = 0.5
CLIENT_TICK_S = 0.1
BASELINE_LEAD_S = 2.0
MAX_PROCESSES = 64
SHARE_GRACE_S = 120.0  # beyond the sessions' duration: handshakes, refusals, the last frames
LAG_METRIC = "lipstream_frame_lag_seconds_bucket"
RSS_METRIC = "lipstream_resident_memory_bytes"
CEILING_METRIC = "lipstream_memory_ceiling_bytes"
KINDS = ("silent", "partial", "sessions")
MIB = float(1 << 20)


@dataclass
class ProbeReport:
    """One ``/healthz``'s answers during the storm: how many, how many failed (no 200
    within ``PROBE_TIMEOUT_S``), and the latency percentiles of those answered (ms)."""

    url: str
    probes: int = 0
    failed: int = 0
    latency_ms: Summary = field(default_factory=dict)


@dataclass
class StormReport:
    """How a storm's connections ended, the admitted sessions' lag on the client's clock,
    how the health probes fared and the server's peak memory against its ceiling."""

    kind: str
    connections: int
    baseline: int = 0
    processes: int = 1
    outcomes: dict[str, int] = field(default_factory=dict)
    refusals: dict[str, int] = field(default_factory=dict)
    admitted: int = 0
    lag_ms: Summary = field(default_factory=dict)
    baseline_lag_ms: Summary = field(default_factory=dict)
    lag_blocks: int = 0
    client_loop_lag_ms: Summary = field(default_factory=dict)
    healthz: dict[str, ProbeReport] = field(default_factory=dict)
    peak_rss_mb: float | None = None
    rss_source: str = ""
    memory_ceiling_mb: float | None = None
    server_lag_p50_s: float | None = None
    server_lag_p99_s: float | None = None
    elapsed_s: float = 0.0


@dataclass
class _Lags:
    """One session's block lags (ms, client clock) and whether it was admitted."""

    values: list[float] = field(default_factory=list)
    admitted: bool = False


@dataclass(frozen=True)
class _Plan:
    """What every storm connection does."""

    url: str
    kind: str
    duration_s: float
    engine: str
    character: str
    latency_budget_ms: float | None


@dataclass
class _ShareResult:
    """How one client process's connections ended, their lags, and its own loop's lag."""

    outcomes: list[str]
    lags: list[_Lags]
    ticks: list[float]


async def _share(plan: _Plan, count: int, tick: bool) -> _ShareResult:
    """Open ``count`` connections of ``plan`` at once; with ``tick``, time this loop too."""
    ticks: list[float] = []
    ticking = asyncio.create_task(_client_ticks(ticks)) if tick else None
    lags = [_Lags() for _ in range(count)]
    if plan.kind == "sessions":
        jobs = [
            _session(
                plan.url,
                plan.engine,
                plan.character,
                plan.duration_s,
                plan.latency_budget_ms,
                each,
            )
            for each in lags
        ]
    else:
        jobs = [_raw(plan.url, plan.kind == "partial", plan.duration_s) for _ in range(count)]
    outcomes = list(await asyncio.gather(*jobs))
    if ticking is not None:
        ticking.cancel()
    return _ShareResult(outcomes, lags, ticks)


def _start_share(
    context: Any, plan: _Plan, count: int, go: EventType
) -> tuple[multiprocessing.process.BaseProcess, Connection]:
    """A client process for ``count`` of the storm's connections, started; it says "ready"
    on the pipe, waits for ``go``, then sends its ``_ShareResult``."""
    answers, sender = context.Pipe(duplex=False)
    process = context.Process(target=_share_process, args=(plan, count, go, sender), daemon=True)
    process.start()
    return process, answers


def _share_process(plan: _Plan, count: int, go: EventType, answers: Connection) -> None:
    answers.send("ready")
    go.wait()
    answers.send(asyncio.run(_share(plan, count, tick=True)))


async def storm(
    url: str,
    kind: str,
    connections: int,
    duration_s: float = 20.0,
    engine: str = "viseme-lerp",
    character: str = "demo",
    healthz_url: str | None = None,
    latency_budget_ms: float | None = None,
    health_port_url: str | None = None,
    baseline: int = 0,
    server_pid: int | None = None,
    processes: int = 1,
) -> StormReport:
    """Open ``baseline`` sessions, then ``connections`` of ``kind`` against the WebSocket
    ``url`` at once (see above), shared among ``processes`` client processes. The probes
    ask ``healthz_url`` (default: ``/healthz`` of the serving port) and ``health_port_url``
    if given. Sessions ask for ``latency_budget_ms``. ``server_pid``: read the server's
    memory from ``/proc``."""
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {', '.join(KINDS)}, not {kind!r}")
    if not 1 <= processes <= MAX_PROCESSES:
        raise ValueError(f"processes must be within 1..{MAX_PROCESSES}, not {processes}")
    base = _http_base(url)
    report = StormReport(kind, connections, baseline, processes)
    metrics_before = _metrics(base)
    lag_before = _lag_buckets(metrics_before)
    ceiling = _metric_sum(metrics_before, CEILING_METRIC)
    report.memory_ceiling_mb = None if ceiling is None else ceiling / MIB
    started = time.monotonic()
    context = multiprocessing.get_context("spawn")
    stop = context.Event()
    answers, sender = context.Pipe(duplex=False)
    probes = {"serving": healthz_url or f"{base}/healthz"}
    if health_port_url is not None:
        probes["health_port"] = health_port_url
    watcher = context.Process(
        target=_watch, args=(probes, f"{base}/metrics", server_pid, stop, sender), daemon=True
    )
    watcher.start()
    if answers.poll(PROBE_START_S):
        answers.recv()  # probing from now on
    plan = _Plan(url, kind, duration_s, engine, character, latency_budget_ms)
    counts = [connections // processes + (i < connections % processes) for i in range(processes)]
    own = [] if baseline else counts[:1]  # the baseline sessions have this process to themselves
    go = context.Event()
    helpers = [_start_share(context, plan, count, go) for count in counts[len(own) :]]
    for _, pipe in helpers:  # each has imported its modules and waits for go
        if not await asyncio.to_thread(pipe.poll, PROBE_START_S):
            raise RuntimeError("a storm client process did not start")
        pipe.recv()
    ticks: list[float] = []
    ticking = asyncio.create_task(_client_ticks(ticks))
    lead = BASELINE_LEAD_S if baseline else 0.0
    steady = [_Lags() for _ in range(baseline)]
    steady_jobs = [
        asyncio.create_task(
            _session(url, engine, character, duration_s + 2 * lead, latency_budget_ms, lags)
        )
        for lags in steady
    ]
    await asyncio.sleep(lead)
    go.set()
    shares = [await _share(plan, count, tick=False) for count in own]
    for process, pipe in helpers:
        if await asyncio.to_thread(pipe.poll, duration_s + SHARE_GRACE_S):
            shares.append(pipe.recv())
        process.join(PROBE_START_S)
    baseline_outcomes = await asyncio.gather(*steady_jobs)
    ticking.cancel()
    outcomes = [outcome for share in shares for outcome in share.outcomes]
    stormed = [lags for share in shares for lags in share.lags]
    ticks += [tick for share in shares for tick in share.ticks]
    stop.set()
    if answers.poll(PROBE_EVERY_S + PROBE_TIMEOUT_S + PROBE_START_S):
        watched: dict[str, Any] = answers.recv()
        report.healthz = {
            name: ProbeReport(probes[name], count, failed, summarize(latencies, LAG_STATISTICS))
            for name, (count, failed, latencies) in watched["probes"].items()
        }
        peak = watched["peak_rss_bytes"]
        report.peak_rss_mb = None if peak is None else peak / MIB
        report.rss_source = watched["rss_source"]
    watcher.join(PROBE_START_S)
    report.elapsed_s = time.monotonic() - started
    report.outcomes = dict(Counter(outcomes))
    if baseline:
        report.outcomes.update({f"baseline:{k}": n for k, n in Counter(baseline_outcomes).items()})
    report.refusals = refusals(outcomes)
    report.admitted = sum(lags.admitted for lags in stormed)
    storm_lags = [value for lags in stormed for value in lags.values]
    report.lag_ms = summarize(
        storm_lags + [v for lags in steady for v in lags.values], LAG_STATISTICS
    )
    report.baseline_lag_ms = summarize([v for lags in steady for v in lags.values], LAG_STATISTICS)
    report.lag_blocks = len(storm_lags) + sum(len(lags.values) for lags in steady)
    report.client_loop_lag_ms = summarize(ticks, LAG_STATISTICS)
    if kind == "sessions":
        lag = _difference(_lag_buckets(_metrics(base)), lag_before)
        report.server_lag_p50_s, report.server_lag_p99_s = _quantile(lag, 0.5), _quantile(lag, 0.99)
    return report


def refusals(outcomes: list[str]) -> dict[str, int]:
    """The refused connections by reason: ``server_busy`` by its ``details.reason`` (as an
    ``error`` or as the JSON body of an upgrade refused with HTTP 503), an upgrade refused
    with an HTTP status and no error body (``http_503``: shed or past the connection cap),
    another error code."""
    counted: Counter[str] = Counter()
    for outcome in outcomes:
        if outcome.startswith("server_busy:"):
            counted[outcome.split(":", 1)[1]] += 1
        elif outcome.startswith("http_"):
            counted[outcome] += 1
        elif outcome.startswith("error:"):
            counted[outcome.split(":", 1)[1]] += 1
    return dict(counted)


def block_lag_ms(first_frame: int, fps: float, sent: list[float], arrived: float) -> float | None:
    """The lag (ms) of a frames block whose first row is frame ``first_frame`` at ``fps``,
    arriving at ``arrived``: from the send of the message covering that frame (``sent``:
    the send times of the phonemes messages, one per ``PHONEME_S``, then of ``end``)."""
    if not sent:
        return None
    index = min(math.floor(first_frame / fps / PHONEME_S + 1e-9), len(sent) - 1)
    return 1000.0 * (arrived - sent[index])


async def _session(
    url: str,
    engine: str,
    character: str,
    duration_s: float,
    latency_budget_ms: float | None,
    lags: _Lags,
) -> str:
    reader: asyncio.Task[None] | None = None
    try:
        async with AsyncClient(url, open_timeout=30.0) as client:
            stream = await client.start(engine, character, latency_budget_ms=latency_budget_ms)
            await stream.ready()
            lags.admitted = True
            sent: list[float] = []
            reader = asyncio.create_task(_arrivals(stream, sent, lags.values))
            began = time.monotonic()
            for index in range(round(duration_s / PHONEME_S)):
                label = PHONEMES[index % len(PHONEMES)]
                sent.append(time.monotonic())
                await stream.send_phonemes([(label, index * PHONEME_S, (index + 1) * PHONEME_S)])
                await asyncio.sleep(max(0.0, began + (index + 1) * PHONEME_S - time.monotonic()))
            sent.append(time.monotonic())
            await stream.end()
            await reader
            await stream.done()
            return "finished"
    except ServerBusy as busy:
        reason = busy.error.details.get("reason") if busy.error is not None else None
        return f"server_busy:{reason}"
    except HandshakeRejected as rejected:
        if rejected.error is not None and rejected.error.code == "server_busy":
            return f"server_busy:{rejected.error.details.get('reason')}"
        return f"http_{rejected.status}"
    except LipstreamServerError as error:
        if error.code == "server_busy":
            return f"server_busy:{error.details.get('reason')}"
        return f"error:{error.code}"
    except LipstreamClientError as error:
        return f"failed:{type(error).__name__}"
    except (OSError, TimeoutError) as error:
        return f"failed:{type(error).__name__}"
    finally:
        if reader is not None and not reader.done():
            reader.cancel()


async def _arrivals(stream: Stream, sent: list[float], lags: list[float]) -> None:
    """Stamp each frames block of ``stream`` as it arrives, until ``done``."""
    async for block in stream.frames():
        lag = block_lag_ms(block.first_frame, block.fps, sent, time.monotonic())
        if lag is not None:
            lags.append(lag)


async def _client_ticks(lags_ms: list[float]) -> None:
    """How late a timer every ``CLIENT_TICK_S`` runs on this (the client's) event loop."""
    loop = asyncio.get_running_loop()
    due = loop.time() + CLIENT_TICK_S
    while True:
        await asyncio.sleep(max(0.0, due - loop.time()))
        lags_ms.append(1000.0 * max(0.0, loop.time() - due))
        due = loop.time() + CLIENT_TICK_S


async def _raw(url: str, partial: bool, duration_s: float) -> str:
    """A socket that says nothing (or half a head); how it ended within ``duration_s``."""
    parts = urlsplit(url)
    try:
        reader, writer = await asyncio.wait_for(
            asyncio.open_connection(parts.hostname, parts.port), 30.0
        )
    except (OSError, TimeoutError) as error:
        return f"connect_failed:{type(error).__name__}"
    try:
        if partial:
            writer.write(b"GET /healthz HTTP/1.1\r\nHost: storm\r\nX-Half: ")
        answer = await asyncio.wait_for(reader.read(), duration_s)
        return "refused_503" if answer.startswith(b"HTTP/1.1 503") else "closed_by_server"
    except TimeoutError:
        return "still_open"
    except OSError:
        return "reset_by_server"
    finally:
        writer.close()


def _watch(
    probes: dict[str, str],
    metrics_url: str,
    server_pid: int | None,
    stop: EventType,
    answers: Connection,
) -> None:
    """Probe each of ``probes`` (name: ``/healthz`` URL) and sample the server's memory, each
    in a thread, until ``stop`` is set (at least once each); send "probing" when it starts,
    then {"probes": {name: (probes, failed, latencies ms)}, "peak_rss_bytes", "rss_source"}.
    Runs in a process of its own, so the storm's own load does not delay it."""
    answers.send("probing")
    results: dict[str, tuple[int, int, list[float]]] = {}
    peak: list[float] = []
    threads = [
        threading.Thread(target=_probe_until, args=(name, url, stop, results))
        for name, url in probes.items()
    ]
    threads.append(
        threading.Thread(target=_memory_until, args=(metrics_url, server_pid, stop, peak))
    )
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    source = f"/proc/{server_pid}" if server_pid is not None else RSS_METRIC
    answers.send(
        {"probes": results, "peak_rss_bytes": max(peak, default=None), "rss_source": source}
    )


def _probe_until(
    name: str, url: str, stop: EventType, results: dict[str, tuple[int, int, list[float]]]
) -> None:
    probes, failed, latencies = 0, 0, []
    while True:
        began = time.monotonic()
        ok = _healthy(url)
        probes += 1
        if ok:
            latencies.append(1000 * (time.monotonic() - began))
        else:
            failed += 1
        if stop.wait(PROBE_EVERY_S):
            break
    results[name] = (probes, failed, latencies)


def _memory_until(
    metrics_url: str, server_pid: int | None, stop: EventType, peak: list[float]
) -> None:
    from .soak import process_tree_rss

    while True:
        if server_pid is not None:
            resident: float | None = process_tree_rss(server_pid)
        else:
            resident = _metric_sum(_fetch(metrics_url, PROBE_TIMEOUT_S), RSS_METRIC)
        if resident is not None:
            peak.append(float(resident))
        if stop.wait(RSS_EVERY_S):
            break


def _healthy(url: str) -> bool:
    opener = urllib.request.build_opener(urllib.request.ProxyHandler({}))
    try:
        with opener.open(url, timeout=PROBE_TIMEOUT_S) as answer:
            return bool(answer.status == 200)
    except OSError:
        return False


def _http_base(url: str) -> str:
    parts = urlsplit(url)
    scheme = "https" if parts.scheme == "wss" else "http"
    return f"{scheme}://{parts.netloc}"


def _fetch(url: str, timeout_s: float) -> str:
    opener = urllib.request.build_opener(urllib.request.ProxyHandler({}))
    try:
        with opener.open(url, timeout=timeout_s) as answer:
            return str(answer.read().decode())
    except OSError:
        return ""


def _metrics(base: str) -> str:
    return _fetch(f"{base}/metrics", 10.0)


def _metric_sum(text: str, name: str) -> float | None:
    """The sum of the samples of ``name`` (unlabelled or not) in an exposition; None if
    absent."""
    values = [
        float(line.rsplit(" ", 1)[1])
        for line in text.splitlines()
        if line.startswith(name + " ") or line.startswith(name + "{")
    ]
    return sum(values) if values else None


def _lag_buckets(text: str) -> dict[float, float]:
    """Cumulative counts of the server's frame-lag histogram, summed over engines."""
    buckets: dict[float, float] = {}
    for line in text.splitlines():
        if line.startswith(LAG_METRIC + "{"):
            labels, value = line.rsplit(" ", 1)
            bound = labels.split('le="', 1)[1].split('"', 1)[0]
            key = float("inf") if bound == "+Inf" else float(bound)
            buckets[key] = buckets.get(key, 0.0) + float(value)
    return buckets


def _difference(after: dict[float, float], before: dict[float, float]) -> dict[float, float]:
    return {bound: count - before.get(bound, 0.0) for bound, count in after.items()}


def _quantile(cumulative: dict[float, float], q: float) -> float | None:
    """The smallest bucket bound that at least ``q`` of the observations fall under."""
    total = cumulative.get(float("inf"), 0.0)
    if total <= 0:
        return None
    for bound in sorted(cumulative):
        if cumulative[bound] >= q * total:
            return bound
    return None


def storm_results(report: StormReport, command: list[str]) -> dict[str, Any]:
    """The run as JSON: the report with the machine, the date and the command."""
    return {
        "tool": f"lipstream loadtest storm {__version__}",
        "date": datetime.now(UTC).isoformat(timespec="seconds"),
        "command": shlex.join(["lipstream", *command[1:]]),
        "machine": {**machine(), "load_average": list(os.getloadavg())},
        "report": asdict(report),
    }


def write_storm_results(results: dict[str, Any], path: Path, name: str) -> None:
    """Put ``results`` in the JSON object in ``path`` under ``name``, keeping its other runs."""
    runs: dict[str, Any] = {}
    if path.is_file():
        loaded = json.loads(path.read_text(encoding="utf-8"))
        if isinstance(loaded, dict):
            runs = loaded
    runs[name] = results
    write_results(runs, path)
