"""The ``lipstream loadtest`` command: its options, and one handler per run.

Sketch: ``lipstream loadtest [options]`` is the Audio2Face-3D style load
test (``load``); ``lipstream loadtest capacity`` searches for the most
sessions a server holds under a lag limit (``capacity``); ``lipstream
loadtest soak`` runs valid sessions among hostile clients (``soak``); ``lipstream
loadtest storm`` opens a burst of connections of one kind at once (``storm``); ``lipstream
loadtest cpu`` compares the server's CPU per session-second with the reference server's
(``cpu_per_session``). The options that
name the target and shape the sessions are declared once (``_target_options``)
and given to each. The CLI (``lipstream.cli``) builds this part of its one
parser with ``add_loadtest_parser``; the handlers import their run lazily, so
building the parser imports no client code.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from dataclasses import replace
from datetime import UTC, datetime
from typing import TYPE_CHECKING, Any

from lipstream_client.messages import ENCODINGS

from ..config import Settings
from ..results_file import write_results

if TYPE_CHECKING:
    from ..cli.commands import Commands


def default_url(settings: Settings) -> str:
    """``/v1/stream`` of the configured server, reached through loopback when it binds
    every interface (0.0.0.0, ::)."""
    host = "127.0.0.1" if settings.host in ("0.0.0.0", "::", "") else settings.host
    return f"ws://{host}:{settings.port}/v1/stream"


def _target_options(parser: argparse.ArgumentParser, *, required_target: bool) -> None:
    parser.add_argument(
        "--url",
        help="loopback ws:// URL of /v1/stream "
        "(default: ws://$LIPSTREAM_HOST:$LIPSTREAM_PORT/v1/stream)",
    )
    if required_target:
        parser.add_argument(
            "--engine",
            required=True,
            help=(
                "engine of every session; capacity also takes a comma-separated list, or 'all' "
                "(each of the character's)"
            ),
        )
        parser.add_argument("--character", required=True, help="character of every session")
    else:
        parser.add_argument("--engine", help="default: the server's first character's first engine")
        parser.add_argument("--character", help="default: the server's first character")
    parser.add_argument("--fps", type=float, default=60.0, help="frame rate requested (default 60)")
    parser.add_argument(
        "--encoding",
        choices=ENCODINGS,
        default="msgpack",
        help="wire encoding (default msgpack)",
    )
    parser.add_argument(
        "--lead-ms", type=float, default=0.0, help="send each phoneme this long before its start"
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of the synthetic clips")
    parser.add_argument("--token", help="bearer token, if the server requires one")


def _budget_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--latency-budget-ms", type=float, help="latency_budget_ms of every request (default none)"
    )


def _load_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--workers",
        type=int,
        default=1,
        help="load-generating processes sharing the sessions (one core each)",
    )
    parser.add_argument(
        "--probe-phonemes",
        type=int,
        default=0,
        help="also time the first frame of requests of this many phonemes "
        "sent whole, on one extra connection",
    )


def _config(args: argparse.Namespace, settings: Settings, **fields: Any) -> Any:
    from .load import LoadTestConfig

    return LoadTestConfig(
        url=args.url or default_url(settings),
        fps=args.fps,
        engine=args.engine,
        character=args.character,
        encoding=args.encoding,
        lead_ms=args.lead_ms,
        seed=args.seed,
        token=args.token,
        workers=args.workers,
        probe_phonemes=args.probe_phonemes,
        **fields,
    )


def _loadtest(args: argparse.Namespace, settings: Settings) -> None:
    from .load import format_table, loadtest

    config = _config(
        args,
        settings,
        streams=args.streams,
        requests=args.requests,
        clips_s=tuple(args.clips),
        latency_budget_ms=args.latency_budget_ms,
        pause_s=args.pause,
        max_duration_s=args.max_duration,
    )
    path = settings.results_file(args.results, "loadtest.json")
    results = loadtest(config)
    write_results(results, path)
    print(json.dumps(results, indent=2) if args.json else format_table(results))
    print(f"results written to {path}", file=sys.stderr)


def _capacity(args: argparse.Namespace, settings: Settings) -> None:
    from .capacity import CapacitySearch, find_capacity, read_results, record_search

    path = settings.results_file(args.results, "capacity.json")
    read_results(path)  # before minutes of searching, not after
    base = _config(args, settings, latency_budget_ms=args.latency_budget_ms)
    engines = _capacity_engines(base.url, args.engine, args.character, args.token)
    references: dict[Any, dict[str, Any]] = {}
    for engine in engines:
        search = CapacitySearch(
            replace(base, engine=engine),
            clip_s=args.clip,
            lag_limit_ms=args.lag_limit_ms,
            start=args.start,
            max_streams=args.max_streams,
            resolution=args.resolution,
            pause_s=args.pause,
            reference=not args.no_reference,
        )
        print(f"{engine}:")
        result = find_capacity(search, progress=print, references=references)
        result["date"] = datetime.now(UTC).isoformat(timespec="seconds")
        result["command"] = "lipstream " + shlex.join(sys.argv[1:])
        record_search(path, result)
        print(f"{_capacity_line(result, args)}; written to {path}")


def _capacity_engines(url: str, engine: str, character: str, token: str | None) -> list[str]:
    """The engines of ``engine``, a comma-separated list, or with ``all`` every engine the
    server has a model of ``character`` for."""
    if engine != "all":
        return [name.strip() for name in engine.split(",") if name.strip()]
    from lipstream_client.rest import RestClient

    from ..errors import InvalidRequestError
    from .load import HTTP_TIMEOUT_S

    for listed in RestClient(url, token, timeout=HTTP_TIMEOUT_S).characters():
        if listed.name == character and listed.engines:
            return list(listed.engines)
    raise InvalidRequestError(f"the server has no model of {character!r}", where="--character")


def _capacity_line(result: dict[str, Any], args: argparse.Namespace) -> str:
    line = (
        f"capacity of {result['engine']}: {result['capacity_streams']} sessions at "
        f"{args.fps:g} fps with p99 lag < {args.lag_limit_ms:g} ms (lead {args.lead_ms:g} ms)"
    )
    reference = result.get("reference")
    if reference is not None:
        ratio = result["capacity_ratio"]
        line += (
            f"; reference server {reference['capacity_streams']} sessions, ratio "
            f"{'-' if ratio is None else f'{ratio:.2f}'}"
        )
    return line


def _add_capacity_parser(runs: Commands) -> None:
    capacity = runs.add_parser(
        "capacity",
        help="the most concurrent real-time sessions the server holds under a lag limit",
        description="Find the most concurrent real-time sessions a lipstream server on this "
        "machine holds with p99 frame lag under a limit.",
    )
    _target_options(capacity, required_target=True)
    _load_options(capacity)
    _budget_option(capacity)
    capacity.add_argument("--clip", type=float, default=10.0, help="clip length in seconds")
    capacity.add_argument(
        "--lag-limit-ms",
        type=float,
        default=50.0,
        help="a session count passes when its p99 frame lag is under this (default 50)",
    )
    capacity.add_argument("--start", type=int, default=100, help="first session count tried")
    capacity.add_argument(
        "--max-streams", type=int, default=1000, help="largest session count tried (default 1000)"
    )
    capacity.add_argument(
        "--resolution",
        type=int,
        default=25,
        help="stop when the boundary is known to this many sessions",
    )
    capacity.add_argument("--pause", type=float, default=3.0, help="seconds between probes")
    capacity.add_argument(
        "--no-reference",
        action="store_true",
        help="skip the reference server's search (no capacity ratio)",
    )
    capacity.add_argument(
        "--results",
        help="JSON file to write the results to (default $LIPSTREAM_HOME/bench/capacity.json)",
    )
    capacity.set_defaults(run=_capacity)


def _cpu(args: argparse.Namespace, settings: Settings) -> None:
    from .cpu_per_session import (
        RESULTS_NAME,
        CpuComparison,
        compare_cpu,
        comparison_line,
        read_results,
        record_run,
    )

    path = settings.results_file(args.results, RESULTS_NAME)
    read_results(path)  # before minutes of measuring, not after
    base = _config(args, settings, streams=args.streams, latency_budget_ms=args.latency_budget_ms)
    command = "lipstream " + shlex.join(sys.argv[1:])
    for engine in _capacity_engines(base.url, args.engine, args.character, args.token):
        comparison = CpuComparison(
            replace(base, engine=engine),
            duration_s=args.duration,
            rounds=args.rounds,
            pause_s=args.pause,
        )
        print(f"{engine}:")
        result = compare_cpu(comparison, progress=print)
        record_run(path, result, command)
        print(f"{comparison_line(result)}; written to {path}")


def _add_cpu_parser(runs: Any) -> None:
    cpu = runs.add_parser(
        "cpu",
        help="the server's CPU per session-second beside the reference server's",
        description="Hold a number of real-time sessions for a fixed time against the server "
        "and against the reference server (the same messages, no synthesis), alternating "
        "A B A B in one run; read each server's CPU time from /proc and report CPU ms per "
        "session-second for each, their ratio, p99 frame lag and whether the count was held.",
    )
    _target_options(cpu, required_target=True)
    _load_options(cpu)
    _budget_option(cpu)
    cpu.add_argument("--streams", type=int, default=100, help="concurrent sessions (default 100)")
    cpu.add_argument(
        "--duration", type=float, default=20.0, help="seconds each leg streams (default 20)"
    )
    cpu.add_argument(
        "--rounds", type=int, default=2, help="pairs of legs, server then reference (default 2)"
    )
    cpu.add_argument("--pause", type=float, default=2.0, help="seconds between legs")
    cpu.add_argument(
        "--results",
        help="JSON file to add the run to (default $LIPSTREAM_HOME/bench/cpu_per_session.json)",
    )
    cpu.set_defaults(run=_cpu)


def _soak(args: argparse.Namespace, settings: Settings) -> None:
    from .soak import SoakConfig, format_report, soak

    config = SoakConfig(
        url=args.url or default_url(settings),
        duration_s=args.duration,
        valid_sessions=args.valid_sessions,
        clip_s=args.clip,
        hostile_per_kind=args.hostile,
        kinds=tuple(args.kinds),
        engine=args.engine,
        character=args.character,
        fps=args.fps,
        encoding=args.encoding,
        lead_ms=args.lead_ms,
        healthz_interval_s=args.healthz_interval,
        server_pid=args.server_pid,
        pq_phonemes=args.pq_phonemes,
        flood_seconds=args.flood_seconds,
        flood_fps=args.flood_fps,
        seed=args.seed,
        token=args.token,
        hostile_niceness=args.hostile_niceness,
    )
    path = settings.results_file(args.results, "soak.json")
    results = soak(config, command="lipstream " + shlex.join(sys.argv[1:]))
    write_results(results, path)
    print(json.dumps(results, indent=2) if args.json else format_report(results))
    print(f"results written to {path}", file=sys.stderr)


def _add_soak_parser(runs: Commands) -> None:
    from .hostile import HOSTILE_KINDS, HOSTILE_NICENESS

    soak = runs.add_parser(
        "soak",
        help="valid real-time sessions among hostile clients, for a bounded time",
        description="Valid real-time sessions among hostile clients (silent sockets, partial "
        "headers, PQ searches, JSON floods, many requests, clients that stop reading, "
        "malformed messages, oversized heads, audio floods, PQ on many connections, JSON "
        "REST floods left unread, one client's flood of connections) against a lipstream "
        "server on this machine: the valid sessions' lag, /healthz latency, peak server "
        "memory against its ceiling and undocumented errors.",
    )
    _target_options(soak, required_target=False)
    soak.add_argument("--duration", type=float, default=60.0, help="seconds (at most 3600)")
    soak.add_argument("--valid-sessions", type=int, default=10, help="concurrent valid sessions")
    soak.add_argument("--clip", type=float, default=5.0, help="valid clip length in seconds")
    soak.add_argument("--hostile", type=int, default=2, help="concurrent clients of each kind")
    soak.add_argument(
        "--kinds", nargs="+", default=list(HOSTILE_KINDS), help="hostile kinds to run"
    )
    soak.add_argument(
        "--healthz-interval", type=float, default=0.1, help="seconds between /healthz polls"
    )
    soak.add_argument(
        "--server-pid",
        type=int,
        help="read the server's memory from /proc/PID (and its children); "
        "default: process_resident_memory_bytes from /metrics",
    )
    soak.add_argument(
        "--pq-phonemes", type=int, default=1000, help="phonemes of each PQ-search request"
    )
    soak.add_argument(
        "--flood-seconds", type=float, default=99.0, help="speech seconds of each JSON flood"
    )
    soak.add_argument("--flood-fps", type=float, default=1000.0, help="fps of each JSON flood")
    soak.add_argument(
        "--hostile-niceness",
        type=int,
        default=HOSTILE_NICENESS,
        help="how much lower the hostile clients' CPU priority is than the measuring clients' "
        "(0: the same)",
    )
    soak.add_argument("--json", action="store_true", help="print JSON instead of a summary")
    soak.add_argument(
        "--results",
        help="JSON file to write the results to (default $LIPSTREAM_HOME/bench/soak.json)",
    )
    soak.set_defaults(run=_soak)


def _storm(args: argparse.Namespace, settings: Settings) -> None:
    import asyncio

    from .storm import storm, storm_results, write_storm_results

    url = args.url or default_url(settings)
    engine, character = args.engine or "viseme-lerp", args.character or "demo"
    report = asyncio.run(
        storm(
            url,
            args.kind,
            args.connections,
            args.duration,
            engine,
            character,
            args.healthz_url,
            args.latency_budget_ms,
            args.health_url,
            args.baseline,
            args.server_pid,
            args.processes,
        )
    )
    results = storm_results(report, sys.argv)
    path = settings.results_file(args.results, "storm.json")
    write_storm_results(results, path, args.name)
    print(f"results written to {path} under {args.name!r}", file=sys.stderr)
    print(json.dumps(results, indent=2))


def _add_storm_parser(runs: Commands) -> None:
    from .storm import KINDS

    storm = runs.add_parser(
        "storm",
        help="a burst of connections of one kind at once: does admission hold?",
        description="Open many connections at once, all of one kind (streaming sessions, "
        "silent sockets or half-sent request heads), after a few sessions opened before it; "
        "probe /healthz on both ports and the server's memory from another process "
        "meanwhile, and report how the connections ended, the refusals by reason, the "
        "admitted sessions' frame lag on the client's clock, the probes' latency and the "
        "peak memory against the ceiling.",
    )
    _target_options(storm, required_target=False)
    _budget_option(storm)
    storm.add_argument("--kind", choices=KINDS, default="sessions", help="connection kind")
    storm.add_argument(
        "-n", "--connections", type=int, default=1100, help="connections opened at once"
    )
    storm.add_argument("--duration", type=float, default=20.0, help="seconds per connection")
    storm.add_argument(
        "--baseline",
        type=int,
        default=8,
        help="sessions opened before the storm, streaming through it (default 8)",
    )
    storm.add_argument(
        "--processes",
        type=int,
        default=1,
        help="client processes sharing the storm's connections (default 1; at most 64)",
    )
    storm.add_argument(
        "--healthz-url",
        help="the serving port's probe (default: /healthz of the serving port)",
    )
    storm.add_argument(
        "--health-url",
        help="the liveness port's probe, e.g. http://127.0.0.1:8081/healthz for "
        "LIPSTREAM_HEALTH_PORT=8081",
    )
    storm.add_argument(
        "--server-pid",
        type=int,
        help="read the server's memory from /proc/PID (and its children); "
        "default: lipstream_resident_memory_bytes from /metrics",
    )
    storm.add_argument(
        "--results",
        help="JSON file to add the run to (default $LIPSTREAM_HOME/bench/storm.json)",
    )
    storm.add_argument("--name", default="client_clock", help="the run's key in the results file")
    storm.set_defaults(run=_storm)


def add_loadtest_parser(commands: Commands) -> None:
    """Add ``loadtest`` and its runs to the CLI's subcommands ``commands``."""
    load = commands.add_parser(
        "loadtest",
        help="concurrent real-time sessions against a server on this machine",
        description="Concurrent real-time sessions against a lipstream server on this machine; "
        "with a run name, a capacity search, a soak or a storm. "
        "Give a run's options after its name.",
    )
    _target_options(load, required_target=False)
    _load_options(load)
    load.add_argument("--streams", type=int, default=10, help="concurrent sessions")
    load.add_argument("--requests", type=int, default=30, help="requests per clip length")
    load.add_argument(
        "--clips", type=float, nargs="+", default=[5.0, 10.0, 20.0], help="clip lengths in seconds"
    )
    _budget_option(load)
    load.add_argument("--pause", type=float, default=3.0, help="seconds between clip lengths")
    load.add_argument(
        "--max-duration",
        type=float,
        default=600.0,
        help="refuse runs planned longer than this many seconds (at most 3600)",
    )
    load.add_argument("--json", action="store_true", help="print JSON instead of a table")
    load.add_argument(
        "--results",
        help="JSON file to write the results to (default $LIPSTREAM_HOME/bench/loadtest.json)",
    )
    load.set_defaults(run=_loadtest)
    runs = load.add_subparsers(dest="loadtest_run", metavar="{capacity,cpu,soak,storm}")
    _add_capacity_parser(runs)
    _add_cpu_parser(runs)
    _add_soak_parser(runs)
    _add_storm_parser(runs)
