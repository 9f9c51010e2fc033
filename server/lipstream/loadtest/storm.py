"""A connection storm against a running server: do admission and the health probe hold?

Sketch: ``storm`` opens ``connections`` connections at once, all of one ``kind``: ``silent``
TCP sockets that never send a byte, ``partial`` ones that send half a request head and stop,
or ``sessions``: WebSockets that each start a request and stream one phoneme every
``PHONEME_S`` (real time) for ``duration_s``, then end it. Meanwhile a probe asks ``GET
/healthz`` every ``PROBE_EVERY_S`` with a ``PROBE_TIMEOUT_S`` timeout. The report counts how
the connections ended (admitted and finished, refused with ``server_busy`` by
``details.reason``, other errors by code, upgrade refused with HTTP 503, closed by the
server before their head, other failures), the probe's answers and slowest answer (the probe
runs in a process of its own, so the storm's load on its own process does not delay it),
and, for sessions, the server's own frame lag over the storm: the difference of its
``lipstream_frame_lag_seconds`` histogram before and after, read from ``/metrics``, as the
bucket bounds the 50th and 99th percentiles fall under. One process drives every connection:
beyond a few hundred streaming sessions, run several stormers at once so the generator is
not the bottleneck.

    lipstream loadtest storm --url ws://127.0.0.1:8000/v1/stream --kind sessions -n 1100
"""

from __future__ import annotations

import asyncio
import multiprocessing
import time
import urllib.request
from collections import Counter
from dataclasses import dataclass, field
from multiprocessing.connection import Connection
from multiprocessing.synchronize import Event as EventType
from urllib.parse import urlsplit

from lipstream_client import (
    AsyncClient,
    HandshakeRejected,
    LipstreamClientError,
    LipstreamServerError,
    ServerBusy,
)

PHONEME_S = 0.08
PHONEMES = ("HH", "AH0", "L", "OW1", "W", "ER1", "L", "D", "sil")
PROBE_EVERY_S = 0.5
PROBE_TIMEOUT_S = 1.0
PROBE_START_S = 30.0  # a spawned process imports the standard library first
LAG_METRIC = "lipstream_frame_lag_seconds_bucket"
KINDS = ("silent", "partial", "sessions")


@dataclass
class StormReport:
    """How a storm's connections ended, and how the health probe fared meanwhile."""

    kind: str
    connections: int
    outcomes: dict[str, int] = field(default_factory=dict)
    probes: int = 0
    probes_failed: int = 0
    slowest_probe_ms: float = 0.0
    lag_p50_s: float | None = None
    lag_p99_s: float | None = None
    elapsed_s: float = 0.0


async def storm(
    url: str,
    kind: str,
    connections: int,
    duration_s: float = 20.0,
    engine: str = "viseme-lerp",
    character: str = "demo",
    healthz_url: str | None = None,
    latency_budget_ms: float | None = None,
) -> StormReport:
    """Open ``connections`` of ``kind`` against the WebSocket ``url`` at once (see above);
    the probe asks ``healthz_url`` (default: ``/healthz`` of the serving port). Sessions ask
    for ``latency_budget_ms``: with a budget at the latency floor (20 ms), the rung has no
    lookahead and every ms of frame lag is the server's."""
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {', '.join(KINDS)}, not {kind!r}")
    base = _http_base(url)
    report = StormReport(kind, connections)
    lag_before = _lag_buckets(base)
    started = time.monotonic()
    context = multiprocessing.get_context("spawn")
    stop = context.Event()
    answers, sender = context.Pipe(duplex=False)
    probe_url = healthz_url or f"{base}/healthz"
    probe = context.Process(target=_probe, args=(probe_url, stop, sender), daemon=True)
    probe.start()
    if answers.poll(PROBE_START_S):
        answers.recv()  # probing from now on
    if kind == "sessions":
        jobs = [
            _session(url, engine, character, duration_s, latency_budget_ms)
            for _ in range(connections)
        ]
    else:
        jobs = [_raw(url, kind == "partial", duration_s) for _ in range(connections)]
    outcomes = await asyncio.gather(*jobs)
    stop.set()
    if answers.poll(PROBE_EVERY_S + PROBE_TIMEOUT_S + PROBE_START_S):
        report.probes, report.probes_failed, report.slowest_probe_ms = answers.recv()
    probe.join(PROBE_START_S)
    report.elapsed_s = time.monotonic() - started
    report.outcomes = dict(Counter(outcomes))
    if kind == "sessions":
        lag = _difference(_lag_buckets(base), lag_before)
        report.lag_p50_s, report.lag_p99_s = _quantile(lag, 0.5), _quantile(lag, 0.99)
    return report


async def _session(
    url: str, engine: str, character: str, duration_s: float, latency_budget_ms: float | None
) -> str:
    try:
        async with AsyncClient(url, open_timeout=30.0) as client:
            stream = await client.start(engine, character, latency_budget_ms=latency_budget_ms)
            await stream.ready()
            began = time.monotonic()
            for index in range(round(duration_s / PHONEME_S)):
                label = PHONEMES[index % len(PHONEMES)]
                await stream.send_phonemes([(label, index * PHONEME_S, (index + 1) * PHONEME_S)])
                await asyncio.sleep(max(0.0, began + (index + 1) * PHONEME_S - time.monotonic()))
            await stream.end()
            await stream.collect()
            return "finished"
    except ServerBusy as busy:
        reason = busy.error.details.get("reason") if busy.error is not None else None
        return f"server_busy:{reason}"
    except HandshakeRejected as rejected:
        return f"http_{rejected.status}"
    except LipstreamServerError as error:
        return f"error:{error.code}"
    except LipstreamClientError as error:
        return f"failed:{type(error).__name__}"
    except (OSError, TimeoutError) as error:
        return f"failed:{type(error).__name__}"


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


def _probe(url: str, stop: EventType, answers: Connection) -> None:
    """Ask ``url`` (a ``/healthz``) until ``stop`` is set (at least once); send "probing"
    when it starts and (probes, failed, slowest ms) at the end. Runs in a process of its
    own, so the storm's own load does not delay it."""
    answers.send("probing")
    probes, failed, slowest_ms = 0, 0, 0.0
    while True:
        began = time.monotonic()
        ok = _healthy(url)
        probes += 1
        failed += not ok
        slowest_ms = max(slowest_ms, 1000 * (time.monotonic() - began))
        if stop.wait(PROBE_EVERY_S):
            break
    answers.send((probes, failed, slowest_ms))


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


def _lag_buckets(base: str) -> dict[float, float]:
    """Cumulative counts of the server's frame-lag histogram, summed over engines."""
    opener = urllib.request.build_opener(urllib.request.ProxyHandler({}))
    try:
        with opener.open(f"{base}/metrics", timeout=10.0) as answer:
            text = answer.read().decode()
    except OSError:
        return {}
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
