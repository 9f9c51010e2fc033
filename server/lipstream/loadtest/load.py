"""``lipstream loadtest``: concurrent real-time sessions against a server on this machine.

Method, after NVIDIA Audio2Face-3D's published benchmark
(``nim_performance_test.py``): for each clip length (5, 10 and 20 s by
default), ``requests`` requests are shared among ``streams`` concurrent
sessions, each a WebSocket connection of the lipstream client SDK that runs
its share one after another. Each request first waits a random delay in
[0, 1) s drawn from a seeded generator (as Audio2Face-3D staggers its
clients), then sends ``start`` and streams the clip's phonemes **paced in
real time**: phoneme k goes out when the utterance clock, started when
``start`` was sent, reaches its start time (minus ``lead_ms``), the way a
TTS produces them; then ``end``, and it reads every frame until ``done``
(``sessions``). With ``workers`` > 1 the sessions are spread over that
many processes (``workers``).

Per request it measures the first-packet latency (``start`` sent to the
first server message, ``ready``: Audio2Face-3D's first packet is likewise
its stream header), the first-frame latency (to the first ``frames``), the
stream's fps (frames received over the time from the first frames to
``done``, as Audio2Face-3D divides its packet count by the same span), and
the lag of every frame against its scheduled time: the arrival time of
frame i minus (time ``start`` was sent + i / fps). Arrival times are taken
as each message comes off the socket. Per clip it reports Audio2Face-3D's
statistics (min, p1, p5, p10, p50, mean, p90, p95, p99, max), frame-lag
percentiles, throughput, errors by code, the CPU seconds of the load
generator and of the server's processes (``cpu``), and, with
``probe_phonemes``, the first-frame latency of whole utterances sent at
once; over all clips, its headline figures
(``stats.overall_summary``).

Safety: the target must be a loopback address (the tool generates load, and
load belongs on one's own machine), the counts are bounded, and a run whose
planned length exceeds ``max_duration_s`` is refused before it starts; a
run that overruns anyway stops starting requests at the deadline.
"""

from __future__ import annotations

import ipaddress
import math
import random
import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any
from urllib.parse import urlsplit, urlunsplit

from lipstream_client.exceptions import LipstreamClientError
from lipstream_client.messages import MAX_FPS, MIN_FPS, Encoding
from lipstream_client.rest import RestClient

from .._version import __version__
from ..errors import InvalidRequestError, LipstreamError
from ..results_file import machine
from .clips import synthetic_clip
from .cpu import ServerCpu
from .sessions import (
    ClipPlan,
    ClipShare,
    RequestRecord,
    event_loop_name,
    run_coroutine,
    run_share,
)
from .stats import A2F_STATISTICS, LAG_STATISTICS, overall_summary, peak_overlap, summarize
from .workers import run_in_workers

__all__ = [
    "LoadTestConfig",
    "NotLoopbackError",
    "RequestRecord",
    "check_config",
    "check_loopback",
    "format_table",
    "loadtest",
    "planned_duration_s",
]

A2F_CLIPS_S: tuple[float, ...] = (5.0, 10.0, 20.0)
MAX_STREAMS = 2000
MAX_REQUESTS = 20_000
MAX_CLIPS = 10
MAX_CLIP_S = 60.0
MAX_DURATION_S = 3600.0
DEFAULT_MAX_DURATION_S = 600.0
MAX_WORKERS = 16
MAX_PROBE_PHONEMES = 1000
PROBE_CLIP_S = 120.0
JITTER_SEED = 45  # the seed of Audio2Face-3D's start-delay generator
MAX_JITTER_S = 1.0
HTTP_TIMEOUT_S = 5.0
_DEFAULT_PORTS = {"ws": 80, "wss": 443}


class NotLoopbackError(LipstreamError):
    code = "not_loopback"


@dataclass(frozen=True)
class LoadTestConfig:
    """What to run: ``streams`` concurrent sessions, ``requests`` requests per clip
    length in ``clips_s`` (seconds), frames at ``fps``. ``engine`` and ``character``
    default to the server's first character. ``pause_s`` separates clip lengths (the
    server's clean-up time); ``lead_ms`` sends each phoneme that much before its start.
    ``workers`` processes share the sessions; ``probe_phonemes`` > 0 also measures the
    first-frame latency of requests of that many phonemes sent whole."""

    url: str = "ws://127.0.0.1:8000/v1/stream"
    streams: int = 10
    requests: int = 30
    clips_s: tuple[float, ...] = A2F_CLIPS_S
    fps: float = 60.0
    engine: str | None = None
    character: str | None = None
    encoding: Encoding = "msgpack"
    latency_budget_ms: float | None = None
    lead_ms: float = 0.0
    pause_s: float = 3.0
    seed: int = 0
    token: str | None = None
    max_duration_s: float = DEFAULT_MAX_DURATION_S
    workers: int = 1
    probe_phonemes: int = 0


def check_loopback(url: str) -> None:
    """NotLoopbackError unless ``url`` names this machine: ``localhost`` or a loopback IP."""
    parts = urlsplit(url)
    if parts.scheme not in ("ws", "wss"):
        raise NotLoopbackError(f"expected a ws:// or wss:// URL, got {url!r}", where="--url")
    host = parts.hostname or ""
    if host == "localhost":
        return
    try:
        loopback = ipaddress.ip_address(host).is_loopback
    except ValueError:
        loopback = False
    if not loopback:
        raise NotLoopbackError(
            f"the load test only targets this machine (localhost, 127.0.0.0/8 or ::1), "
            f"got host {host!r}",
            where="--url",
        )


def planned_duration_s(config: LoadTestConfig) -> float:
    """Upper estimate of the run's wall time: rounds of the longest delay plus clip, and pauses."""
    rounds = math.ceil(config.requests / config.streams)
    return sum(rounds * (MAX_JITTER_S + clip) for clip in config.clips_s) + config.pause_s * max(
        0, len(config.clips_s) - 1
    )


def check_config(config: LoadTestConfig) -> None:
    """InvalidRequestError naming the flag whose value is out of bounds."""
    check_loopback(config.url)
    bounds: list[tuple[str, bool, str]] = [
        ("--streams", 1 <= config.streams <= MAX_STREAMS, f"1..{MAX_STREAMS}"),
        ("--requests", 1 <= config.requests <= MAX_REQUESTS, f"1..{MAX_REQUESTS}"),
        (
            "--clips",
            1 <= len(config.clips_s) <= MAX_CLIPS
            and all(1.0 <= clip <= MAX_CLIP_S for clip in config.clips_s),
            f"1 to {MAX_CLIPS} lengths in [1, {MAX_CLIP_S:g}] s",
        ),
        ("--fps", MIN_FPS <= config.fps <= MAX_FPS, f"[{MIN_FPS:g}, {MAX_FPS:g}]"),
        ("--lead-ms", 0 <= config.lead_ms <= 10_000, "[0, 10000]"),
        ("--pause", 0 <= config.pause_s <= 60, "[0, 60] s"),
        (
            "--max-duration",
            0 < config.max_duration_s <= MAX_DURATION_S,
            f"(0, {MAX_DURATION_S:g}] s",
        ),
        (
            "--workers",
            1 <= config.workers <= min(MAX_WORKERS, config.streams),
            f"1..{MAX_WORKERS}, and at most --streams",
        ),
        (
            "--probe-phonemes",
            0 <= config.probe_phonemes <= MAX_PROBE_PHONEMES,
            f"0..{MAX_PROBE_PHONEMES}",
        ),
    ]
    for flag, ok, allowed in bounds:
        if not ok:
            raise InvalidRequestError(f"must be {allowed}", where=flag)
    planned = planned_duration_s(config)
    if planned > config.max_duration_s:
        raise InvalidRequestError(
            f"this run would take up to {planned:.0f} s, more than the {config.max_duration_s:g} s "
            f"allowed; lower --requests or --clips, or raise --max-duration "
            f"(at most {MAX_DURATION_S:g})",
            where="--max-duration",
        )


def http_base(url: str) -> str:
    """The server's HTTP root for a ``/v1/stream`` WebSocket URL."""
    parts = urlsplit(url)
    scheme = "https" if parts.scheme == "wss" else "http"
    return urlunsplit((scheme, parts.netloc, "", "", ""))


def default_target(url: str, token: str | None = None) -> tuple[str, str]:
    """(engine, character): the first character ``GET /v1/characters`` lists, its first engine."""
    try:
        return RestClient(url, token, timeout=HTTP_TIMEOUT_S).default_target()
    except (OSError, ValueError, KeyError, TypeError, LipstreamClientError) as error:
        raise InvalidRequestError(
            f"cannot list the server's characters at {http_base(url)} "
            f"({error}); pass --engine and --character",
            where="--url",
        ) from None


def _target(config: LoadTestConfig) -> tuple[str, str]:
    engine, character = config.engine, config.character
    if engine is None or character is None:
        found_engine, found_character = default_target(config.url, config.token)
        engine, character = engine or found_engine, character or found_character
    return engine, character


def _present(values: Sequence[float | None]) -> list[float]:
    return [value for value in values if value is not None]


def clip_report(
    plan: ClipPlan, share: ClipShare, wall_s: float, server_cpu_s: float | None
) -> dict[str, Any]:
    """One clip length's figures, keyed as in bench/loadtest.json."""
    records = share.records
    frames = sum(record.frames for record in records)
    slips = [slip for record in records for slip in record.send_slip_ms]
    return {
        "clip_s": plan.clip_s,
        "phonemes": len(plan.spans),
        "requests": len(records),
        "successful_requests": sum(record.error is None for record in records),
        "errors": dict(Counter(record.error for record in records if record.error)),
        "busy_retries": sum(record.busy_retries for record in records),
        "peak_sessions": peak_overlap(share.session_spans),
        "first_packet_latency_ms": summarize(_present([r.first_packet_ms for r in records])),
        "first_frame_latency_ms": summarize(_present([r.first_frame_ms for r in records])),
        "fps": summarize(_present([r.fps for r in records])),
        "frame_lag_ms": summarize(share.frame_lags_ms(plan.fps), LAG_STATISTICS),
        "server_max_lag_ms": summarize(
            _present([r.server_max_lag_ms for r in records]), LAG_STATISTICS
        ),
        "send_slip_ms": summarize(slips, LAG_STATISTICS),
        "probe": _probe_report(plan, share),
        "frames": frames,
        "wall_s": wall_s,
        "throughput_frames_per_s": frames / wall_s if wall_s > 0 else None,
        "throughput_requests_per_s": len(records) / wall_s if wall_s > 0 else None,
        "client_cpu_s": share.cpu_s,
        "server_cpu_s": server_cpu_s,
    }


def _probe_report(plan: ClipPlan, share: ClipShare) -> dict[str, Any] | None:
    if not plan.probe_phonemes:
        return None
    return {
        "phonemes": len(plan.probe_spans[: plan.probe_phonemes]),
        "requests": len(share.probe_ms) + len(share.probe_errors),
        "errors": dict(Counter(share.probe_errors)),
        "first_frame_latency_ms": summarize(share.probe_ms),
    }


def _run_clip(config: LoadTestConfig, plan: ClipPlan, server_cpu: ServerCpu) -> dict[str, Any]:
    began = time.perf_counter()
    server_cpu.mark()
    if config.workers == 1:
        share = run_coroutine(run_share(plan, range(config.requests), config.streams, probe=True))
    else:
        share = run_in_workers(plan, config.requests, config.streams, config.workers, probe=True)
    return clip_report(plan, share, time.perf_counter() - began, server_cpu.mark())


def _plan(
    config: LoadTestConfig,
    engine: str,
    character: str,
    clip_s: float,
    jitter_s: tuple[float, ...],
    deadline: float,
) -> ClipPlan:
    probe_spans = (
        synthetic_clip(PROBE_CLIP_S, seed=config.seed + 1) if config.probe_phonemes else []
    )
    return ClipPlan(
        url=config.url,
        engine=engine,
        character=character,
        encoding=config.encoding,
        token=config.token,
        fps=config.fps,
        lead_ms=config.lead_ms,
        latency_budget_ms=config.latency_budget_ms,
        spans=tuple(synthetic_clip(clip_s, seed=config.seed)),
        jitter_s=jitter_s,
        deadline=deadline,
        probe_phonemes=config.probe_phonemes,
        probe_spans=tuple(probe_spans),
    )


def loadtest(config: LoadTestConfig) -> dict[str, Any]:
    """Run the whole load test and return the results document (see docs/how-to/load-testing.md)."""
    check_config(config)
    engine, character = _target(config)
    generator = random.Random(JITTER_SEED)
    jitter_s = tuple(generator.random() * MAX_JITTER_S for _ in range(config.requests))
    server_cpu = ServerCpu(urlsplit(config.url).port or _DEFAULT_PORTS[urlsplit(config.url).scheme])
    began, cpu_began = time.perf_counter(), time.process_time()
    deadline = began + config.max_duration_s
    clips: list[dict[str, Any]] = []
    for number, clip_s in enumerate(config.clips_s):
        if number:
            time.sleep(config.pause_s)
        plan = _plan(config, engine, character, clip_s, jitter_s, deadline)
        clips.append(_run_clip(config, plan, server_cpu))
    wall_s = time.perf_counter() - began
    parent_cpu_s = time.process_time() - cpu_began
    children_cpu_s = sum(clip["client_cpu_s"] for clip in clips) if config.workers > 1 else 0.0
    server_cpu_s = [clip["server_cpu_s"] for clip in clips]
    return {
        "tool": f"lipstream loadtest {__version__}",
        "method": "Audio2Face-3D nim_performance_test: streams x requests over each clip, "
        "seeded [0, 1) s start delays; phonemes paced in real time",
        "machine": {**machine(), "event_loop": event_loop_name()},
        "config": {**asdict(config), "token": None, "engine": engine, "character": character},
        "statistics": [name for name, _ in A2F_STATISTICS],
        "clips": clips,
        "summary": {
            **overall_summary(clips),
            "requests": sum(clip["requests"] for clip in clips),
            "successful_requests": sum(clip["successful_requests"] for clip in clips),
            "errors": dict(sum((Counter(clip["errors"]) for clip in clips), Counter())),
            "wall_s": wall_s,
            "client_cpu_s": parent_cpu_s + children_cpu_s,
            "server_cpu_s": None if None in server_cpu_s else sum(server_cpu_s),
            "server_processes": len(server_cpu.pids),
        },
    }


def _cell(value: float | None, digits: int = 1) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def format_table(results: dict[str, Any]) -> str:
    """A plain-text table: one row per clip length, then the headline figures."""
    header = (
        f"{'clip s':>6} {'ok/req':>9} {'1st pkt p50':>11} {'p90':>7} {'p95':>7} "
        f"{'p99':>7} {'max':>7} {'fps p1':>7} {'fps p50':>7} {'lag p50':>7} "
        f"{'lag p99':>7} {'frames/s':>9}  errors"
    )
    lines = [header]
    for clip in results["clips"]:
        latency, fps, lag = clip["first_packet_latency_ms"], clip["fps"], clip["frame_lag_ms"]
        errors = ", ".join(f"{code} x{count}" for code, count in clip["errors"].items()) or "-"
        lines.append(
            f"{clip['clip_s']:>6g} {clip['successful_requests']:>4}/{clip['requests']:<4} "
            f"{_cell(latency['p50']):>11} {_cell(latency['p90']):>7} {_cell(latency['p95']):>7} "
            f"{_cell(latency['p99']):>7} {_cell(latency['max']):>7} {_cell(fps['p1']):>7} "
            f"{_cell(fps['p50']):>7} {_cell(lag['p50']):>7} {_cell(lag['p99']):>7} "
            f"{_cell(clip['throughput_frames_per_s'], 0):>9}  {errors}"
        )
    summary = results["summary"]
    lines.append(
        f"worst p99 first-packet latency {_cell(summary['worst_p99_first_packet_latency_ms'])} ms, "
        f"mean {_cell(summary['mean_first_packet_latency_ms'])} ms; lowest p1 fps "
        f"{_cell(summary['lowest_p1_fps'])}; worst p99 frame lag "
        f"{_cell(summary['worst_p99_frame_lag_ms'])} ms; "
        f"{summary['successful_requests']}/{summary['requests']} requests ok in "
        f"{summary['wall_s']:.1f} s (CPU: client {summary['client_cpu_s']:.1f} s, "
        f"server {_cell(summary['server_cpu_s'])} s)"
    )
    for clip in results["clips"]:
        probe = clip["probe"]
        if probe is not None:
            latency = probe["first_frame_latency_ms"]
            lines.append(
                f"{clip['clip_s']:g} s clips: {probe['phonemes']}-phoneme requests "
                f"sent whole, first frame p50 {_cell(latency['p50'])} ms, p99 "
                f"{_cell(latency['p99'])} ms over {probe['requests']} requests"
            )
    return "\n".join(lines)
