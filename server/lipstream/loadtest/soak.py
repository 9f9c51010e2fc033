"""``lipstream loadtest soak``: valid sessions among hostile clients, for a bounded time.

Sketch: for ``duration_s`` seconds ``valid_sessions`` real-time sessions
run clips of ``clip_s`` seconds one after another (the load test's
sessions, ``sessions.run_share``, so their frame lag means the same; a
request under way at the end may finish), while ``hostile_per_kind``
clients of each hostile kind (``hostile``) misbehave over and over in a
forked process of their own, so that their work (reading floods of frames)
never delays the valid sessions' timestamps. Throughout, ``/healthz`` is polled
every ``healthz_interval_s`` on a fresh connection, and the server's
resident memory is sampled: from ``/proc/<pid>/status`` (the process and
its children, such as uvicorn's workers) when ``server_pid`` is given, else
from ``process_resident_memory_bytes`` in ``/metrics`` when the server
exports it. The report gives the valid (admitted) sessions' frame-lag
percentiles and errors, the health checks' latency percentiles and
failures, the peak resident memory against the server's memory ceiling
(``lipstream_memory_ceiling_bytes`` in ``/metrics``, summed over its
workers), each hostile kind's tally, and every error code that
``lipstream_client.errors.ERROR_CODES`` does not document, and every close
code outside ``CloseCode``, seen by anyone.

Safety: as the load test, loopback targets only and bounded counts and time.
"""

from __future__ import annotations

import asyncio
import json
import math
import multiprocessing
import os
import random
import resource
import time
from collections import Counter
from dataclasses import asdict, dataclass, field
from datetime import UTC, datetime
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from lipstream_client.errors import ERROR_CODES, CloseCode
from lipstream_client.exceptions import LipstreamClientError
from lipstream_client.messages import MAX_FPS, MIN_FPS, Encoding
from lipstream_client.rest import RestClient

from .._version import __version__
from ..errors import InvalidRequestError
from ..results_file import machine
from .clips import synthetic_clip
from .hostile import HOSTILE_KINDS, HOSTILE_NICENESS, KindTally, Target, run_kind
from .load import HTTP_TIMEOUT_S, MAX_JITTER_S, check_loopback, http_base
from .sessions import ClipPlan, ClipShare, event_loop_name, run_coroutine, run_share
from .stats import LAG_STATISTICS, summarize
from .workers import WorkerFailed

MAX_DURATION_S = 3600.0
MAX_VALID_SESSIONS = 500
MAX_HOSTILE_PER_KIND = 100
HEALTH_TIMEOUT_S = 10.0
RSS_INTERVAL_S = 0.5
HOSTILE_JOIN_S = 30.0
DEFAULT_PORTS = {"ws": 80, "wss": 443}
_MS = 1000.0


@dataclass(frozen=True)
class SoakConfig:
    """What to run; ``engine`` and ``character`` default to the server's first character.
    ``server_pid``: read the server's memory from ``/proc`` (with its children)."""

    url: str = "ws://127.0.0.1:8000/v1/stream"
    duration_s: float = 60.0
    valid_sessions: int = 10
    clip_s: float = 5.0
    hostile_per_kind: int = 2
    kinds: tuple[str, ...] = HOSTILE_KINDS
    engine: str | None = None
    character: str | None = None
    fps: float = 60.0
    encoding: Encoding = "msgpack"
    lead_ms: float = 0.0
    healthz_interval_s: float = 0.1
    server_pid: int | None = None
    pq_phonemes: int = 1000
    flood_seconds: float = 99.0
    flood_fps: float = 1000.0
    seed: int = 0
    token: str | None = None
    hostile_niceness: int = HOSTILE_NICENESS


def check_soak(config: SoakConfig) -> None:
    """InvalidRequestError naming the flag whose value is out of bounds."""
    check_loopback(config.url)
    unknown = sorted(set(config.kinds) - set(HOSTILE_KINDS))
    bounds: list[tuple[str, bool, str]] = [
        ("--duration", 0 < config.duration_s <= MAX_DURATION_S, f"(0, {MAX_DURATION_S:g}] s"),
        (
            "--valid-sessions",
            1 <= config.valid_sessions <= MAX_VALID_SESSIONS,
            f"1..{MAX_VALID_SESSIONS}",
        ),
        ("--clip", 1.0 <= config.clip_s <= 60.0, "[1, 60] s"),
        (
            "--hostile",
            0 <= config.hostile_per_kind <= MAX_HOSTILE_PER_KIND,
            f"0..{MAX_HOSTILE_PER_KIND}",
        ),
        ("--kinds", not unknown, f"among {', '.join(HOSTILE_KINDS)} (not {', '.join(unknown)})"),
        ("--fps", MIN_FPS <= config.fps <= MAX_FPS, f"[{MIN_FPS:g}, {MAX_FPS:g}]"),
        ("--lead-ms", 0 <= config.lead_ms <= 10_000, "[0, 10000]"),
        ("--healthz-interval", 0.01 <= config.healthz_interval_s <= 60, "[0.01, 60] s"),
        ("--pq-phonemes", 1 <= config.pq_phonemes <= 10_000, "1..10000"),
        ("--flood-seconds", 1.0 <= config.flood_seconds <= 600.0, "[1, 600] s"),
        ("--flood-fps", 0 < config.flood_fps <= 1000, "(0, 1000]"),
        ("--hostile-niceness", 0 <= config.hostile_niceness <= 19, "0..19"),
        (
            "--server-pid",
            config.server_pid is None or Path(f"/proc/{config.server_pid}").is_dir(),
            "the id of a running process",
        ),
    ]
    for flag, ok, allowed in bounds:
        if not ok:
            raise InvalidRequestError(f"must be {allowed}", where=flag)


@dataclass
class _Health:
    latencies_ms: list[float] = field(default_factory=list)
    failures: Counter[str] = field(default_factory=Counter)


@dataclass
class _Memory:
    source: str | None = None
    samples: int = 0
    peak_bytes: int | None = None

    def add(self, value: int | None) -> None:
        if value is not None:
            self.samples += 1
            self.peak_bytes = max(value, self.peak_bytes or 0)


async def http_get(host: str, port: int, path: str) -> tuple[int, bytes]:
    """(status, body) of ``GET path`` on a fresh connection that the server closes."""
    reader, writer = await asyncio.open_connection(host, port)
    try:
        writer.write(f"GET {path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n".encode())
        response = await reader.read()
    finally:
        writer.close()
    head, _, body = response.partition(b"\r\n\r\n")
    status = head.split(b" ", 2)
    if len(status) < 2 or not status[1].isdigit():
        raise ConnectionError(f"not an HTTP response: {head[:40]!r}")
    return int(status[1]), body


async def _poll_health(host: str, port: int, interval_s: float, health: _Health) -> None:
    while True:
        began = time.perf_counter()
        try:
            status, _ = await asyncio.wait_for(http_get(host, port, "/healthz"), HEALTH_TIMEOUT_S)
            if status == 200:
                health.latencies_ms.append((time.perf_counter() - began) * _MS)
            else:
                health.failures[f"http_{status}"] += 1
        except TimeoutError:
            health.failures["timeout"] += 1
        except OSError as error:
            health.failures[type(error).__name__] += 1
        await asyncio.sleep(max(0.0, interval_s - (time.perf_counter() - began)))


def process_tree_rss(pid: int) -> int | None:
    """Resident bytes of ``pid`` and its descendants, from ``/proc``; None if it is gone."""
    parents: dict[int, int] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            parents[int(entry.name)] = int(stat.rsplit(")", 1)[1].split()[1])
    tree, frontier = {pid}, [pid]
    while frontier:
        parent = frontier.pop()
        children = [child for child, of in parents.items() if of == parent and child not in tree]
        tree.update(children)
        frontier.extend(children)
    own = _rss_bytes(pid)
    if own is None:
        return None
    return own + sum(_rss_bytes(member) or 0 for member in tree - {pid})


def _rss_bytes(pid: int) -> int | None:
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return None
    for line in status.splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) * 1024
    return None


def metrics_rss(text: str) -> int | None:
    """The sum of ``process_resident_memory_bytes`` in a Prometheus exposition, if any."""
    return metrics_sum(text, "process_resident_memory_bytes")


def metrics_sum(text: str, name: str) -> int | None:
    """The sum of the samples of ``name`` in a Prometheus exposition, if any."""
    values = [
        float(line.rsplit(" ", 1)[1])
        for line in text.splitlines()
        if line.startswith(name) and line[len(name) : len(name) + 1] in (" ", "{")
    ]
    return int(sum(values)) if values else None


async def memory_ceiling(host: str, port: int) -> int | None:
    """The server's memory ceiling in bytes (all workers), from ``/metrics``; None if it does
    not say."""
    try:
        status, body = await asyncio.wait_for(http_get(host, port, "/metrics"), HEALTH_TIMEOUT_S)
    except (OSError, TimeoutError):
        return None
    if status != 200:
        return None
    return metrics_sum(body.decode("utf-8", "replace"), "lipstream_memory_ceiling_bytes")


async def _sample_memory(config: SoakConfig, host: str, port: int, memory: _Memory) -> None:
    pid = config.server_pid
    memory.source = f"/proc/{pid}" if pid is not None else "/metrics"
    while True:
        if pid is not None:
            memory.add(await asyncio.to_thread(process_tree_rss, pid))
        else:
            try:
                status, body = await asyncio.wait_for(
                    http_get(host, port, "/metrics"), HEALTH_TIMEOUT_S
                )
                if status == 200:
                    memory.add(metrics_rss(body.decode("utf-8", "replace")))
            except (OSError, TimeoutError):
                pass
        await asyncio.sleep(RSS_INTERVAL_S)


def _targets(config: SoakConfig) -> tuple[str, str, str | None, str | None]:
    """(engine, character) of the valid sessions, a character with anime-graph (PQ search)
    and one with hmm (driven by audio alone)."""
    try:
        characters = RestClient(config.url, config.token, timeout=HTTP_TIMEOUT_S).characters()
    except (OSError, ValueError, KeyError, TypeError, LipstreamClientError) as error:
        raise InvalidRequestError(
            f"cannot list the server's characters at {http_base(config.url)} ({error})",
            where="--url",
        ) from None
    served = [c for c in characters if c.engines]
    if not served:
        raise InvalidRequestError("the server lists no character with a model", where="--url")
    engine = config.engine or served[0].engines[0]
    character = config.character or served[0].name
    pq = next((c.name for c in served if "anime-graph" in c.engines), None)
    audio = next((c.name for c in served if "hmm" in c.engines), None)
    return engine, character, pq, audio


def _plan(config: SoakConfig, engine: str, character: str, deadline: float) -> ClipPlan:
    generator = random.Random(config.seed)
    rounds = math.ceil(config.duration_s / config.clip_s) + 1
    return ClipPlan(
        url=config.url,
        engine=engine,
        character=character,
        encoding=config.encoding,
        token=config.token,
        fps=config.fps,
        lead_ms=config.lead_ms,
        latency_budget_ms=None,
        spans=tuple(synthetic_clip(config.clip_s, seed=config.seed)),
        jitter_s=tuple(
            generator.random() * MAX_JITTER_S for _ in range(rounds * config.valid_sessions)
        ),
        deadline=deadline,
    )


async def _measure(
    config: SoakConfig, target: Target, plan: ClipPlan
) -> tuple[ClipShare, _Health, _Memory]:
    """The valid sessions, with the health poll and the memory samples alongside."""
    health, memory = _Health(), _Memory()
    background = [
        asyncio.create_task(
            _poll_health(target.host, target.port, config.healthz_interval_s, health)
        ),
        asyncio.create_task(_sample_memory(config, target.host, target.port, memory)),
    ]
    try:
        share = await run_share(plan, range(len(plan.jitter_s)), config.valid_sessions, False)
    finally:
        for task in background:
            task.cancel()
        await asyncio.gather(*background, return_exceptions=True)
    return share, health, memory


async def _run_hostile(config: SoakConfig, target: Target, deadline: float) -> dict[str, KindTally]:
    tallies = {kind: KindTally() for kind in config.kinds}
    await asyncio.gather(
        *(
            run_kind(kind, target, tallies[kind], deadline)
            for kind in config.kinds
            for _ in range(config.hostile_per_kind)
        )
    )
    return tallies


def _hostile_process(config: SoakConfig, target: Target, deadline: float, pipe: Connection) -> None:
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft != hard:  # the client flood holds thousands of sockets
        resource.setrlimit(resource.RLIMIT_NOFILE, (hard, hard))
    if config.hostile_niceness:
        os.nice(config.hostile_niceness)
    tallies = run_coroutine(_run_hostile(config, target, deadline))
    pipe.send_bytes(json.dumps({kind: t.as_dict() for kind, t in tallies.items()}).encode())
    pipe.close()


def _run(
    config: SoakConfig, target: Target, plan: ClipPlan
) -> tuple[ClipShare, dict[str, dict[str, Any]], _Health, _Memory]:
    """The hostile clients in a forked process of their own, so that reading their floods
    never delays the valid sessions' timestamps; the measurements in this one."""
    context = multiprocessing.get_context("fork")
    receiving, sending = context.Pipe(duplex=False)
    process = context.Process(
        target=_hostile_process,
        name="lipstream-soak-hostile",
        args=(config, target, plan.deadline, sending),
    )
    process.start()
    sending.close()
    try:
        share, health, memory = run_coroutine(_measure(config, target, plan))
        try:
            hostile: dict[str, dict[str, Any]] = json.loads(receiving.recv_bytes())
        except EOFError:
            raise WorkerFailed(
                f"the hostile clients' process ended without results (exit code {process.exitcode})"
            ) from None
    finally:
        process.join(HOSTILE_JOIN_S)
        if process.is_alive():
            process.kill()
            process.join()
    return share, hostile, health, memory


def _undocumented(share: ClipShare, hostile: dict[str, dict[str, Any]]) -> dict[str, int]:
    """Error codes outside ERROR_CODES and close codes outside CloseCode, by anyone."""
    seen: Counter[str] = Counter()
    for record in share.records:
        if record.error is not None:
            seen[record.error] += 1
    for tally in hostile.values():
        seen.update(tally["error_codes"])
        seen.update({f"closed_{code}": n for code, n in tally["closes"].items() if code.isdigit()})
    close_codes = {f"closed_{int(code)}" for code in CloseCode}
    client_side = {"deadline", "timeout", "no_error_reply"}
    return {
        code: count
        for code, count in sorted(seen.items())
        if code not in ERROR_CODES
        and code not in close_codes
        and code not in client_side
        and not code.startswith("http_")
        and not code[:1].isupper()  # client-side exception names
    }


def soak(config: SoakConfig, command: str | None = None) -> dict[str, Any]:
    """Run the soak and return its results document (see docs/how-to/load-testing.md, "Soak");
    ``command``: the command line that ran it, for the record."""
    check_soak(config)
    engine, character, pq_character, audio_character = _targets(config)
    parts = urlsplit(config.url)
    target = Target(
        url=config.url,
        host=parts.hostname or "127.0.0.1",
        port=parts.port or DEFAULT_PORTS[parts.scheme],
        engine=engine,
        character=character,
        encoding=config.encoding,
        token=config.token,
        pq_character=pq_character,
        audio_character=audio_character,
        pq_phonemes=config.pq_phonemes,
        flood_seconds=config.flood_seconds,
        flood_fps=config.flood_fps,
        seed=config.seed,
    )
    ceiling = run_coroutine(memory_ceiling(target.host, target.port))
    date = datetime.now(UTC).isoformat(timespec="seconds")
    began = time.perf_counter()
    plan = _plan(config, engine, character, began + config.duration_s)
    share, hostile, health, memory = _run(config, target, plan)
    started = [record for record in share.records if record.error != "deadline"]
    lag = summarize(share.frame_lags_ms(config.fps), LAG_STATISTICS)
    health_latency = summarize(health.latencies_ms, LAG_STATISTICS)
    undocumented = _undocumented(share, hostile)
    peak = memory.peak_bytes
    return {
        "tool": f"lipstream loadtest soak {__version__}",
        "date": date,
        "command": command,
        "machine": {**machine(), "event_loop": event_loop_name()},
        "config": {
            **asdict(config),
            "kinds": list(config.kinds),
            "token": None,
            "engine": engine,
            "character": character,
        },
        "wall_s": time.perf_counter() - began,
        "valid": {
            "requests": len(started),
            "successful_requests": sum(record.error is None for record in started),
            "errors": dict(Counter(r.error for r in started if r.error is not None)),
            "frames": sum(record.frames for record in started),
            "frame_lag_ms": lag,
            "first_frame_latency_ms": summarize(
                [r.first_frame_ms for r in started if r.first_frame_ms is not None],
                LAG_STATISTICS,
            ),
        },
        "healthz": {
            "polls": len(health.latencies_ms) + sum(health.failures.values()),
            "failures": dict(health.failures),
            "latency_ms": health_latency,
        },
        "server_memory": {
            "source": memory.source,
            "samples": memory.samples,
            "peak_rss_bytes": peak,
            "ceiling_bytes": ceiling,
        },
        "hostile": hostile,
        "undocumented_errors": undocumented,
        "summary": {
            "valid_frame_lag_p99_ms": lag["p99"],
            "healthz_latency_p99_ms": health_latency["p99"],
            "peak_server_rss_bytes": peak,
            "memory_ceiling_bytes": ceiling,
            "peak_rss_of_ceiling": None if peak is None or not ceiling else peak / ceiling,
            "undocumented_errors": sum(undocumented.values()),
        },
    }


def _number(value: float | None, digits: int = 1) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def format_report(results: dict[str, Any]) -> str:
    """The headline figures and one line per hostile kind."""
    valid, health, summary = results["valid"], results["healthz"], results["summary"]
    rss, ceiling = summary["peak_server_rss_bytes"], summary["memory_ceiling_bytes"]
    lines = [
        f"valid sessions: {valid['successful_requests']}/{valid['requests']} requests ok, "
        f"frame lag p50 {_number(valid['frame_lag_ms']['p50'])} ms, "
        f"p99 {_number(summary['valid_frame_lag_p99_ms'])} ms, errors {valid['errors'] or '-'}",
        f"/healthz: {health['polls']} polls, p99 {_number(summary['healthz_latency_p99_ms'])} ms, "
        f"failures {health['failures'] or '-'}",
        f"peak server RSS: {'-' if rss is None else f'{rss / 2**20:.0f} MiB'} "
        f"({results['server_memory']['source']}), ceiling "
        f"{'-' if ceiling is None else f'{ceiling / 2**20:.0f} MiB'}",
        f"undocumented errors: {results['undocumented_errors'] or 'none'}",
    ]
    for kind, tally in results["hostile"].items():
        detail = tally["skipped"] or (
            f"errors {tally['error_codes'] or '-'}, closes {tally['closes'] or '-'}, "
            f"client failures {tally['client_failures'] or '-'}"
        )
        lines.append(f"  {kind:<16} {tally['attempts']:>5} attempts: {detail}")
    return "\n".join(lines)
