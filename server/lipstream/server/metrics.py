"""Prometheus metrics of one server process, served as text on ``GET /metrics``.

Sketch: each app owns a ``CollectorRegistry`` (so several apps in one
process, as in tests, do not collide). Labels have bounded values only: the
loaded engines, the protocol's error codes, the ten message types and the
request outcomes.

Several workers (``--workers N``) share one sum through prometheus_client's
multiprocess mode: with ``PROMETHEUS_MULTIPROC_DIR`` set before the workers
import prometheus_client, every worker writes its values to memory-mapped
files named by its pid there, and each ``/metrics`` merges all files.
Counters and histograms add up over every worker that ever ran (so totals
never go back when a worker is replaced); the gauges are ``live*`` modes,
which count only workers still running. ``multiprocess_directory`` (for the
process that starts the workers) empties a given directory, or makes a
private one when several workers need it and none is given; a worker
forgets its own gauges when it stops (``forget_this_process``), and
``render`` forgets those of workers that died without stopping (killed, or
crashed).
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from prometheus_client import (
    CONTENT_TYPE_LATEST,
    CollectorRegistry,
    Counter,
    Gauge,
    Histogram,
    generate_latest,
)
from prometheus_client.metrics import MetricWrapperBase
from prometheus_client.multiprocess import MultiProcessCollector, mark_process_dead

from .load import MIB, LoadSample
from .tally import StreamTally

LATENCY_BUCKETS_S = (0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0)
JOBS_AHEAD_BUCKETS = (0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 16.0, 32.0, 64.0)
MULTIPROCESS_ENV = "PROMETHEUS_MULTIPROC_DIR"
LIVE_GAUGE_FILES = "gauge_live*_*.db"


class Metrics:
    """The server's counters, gauges and histograms."""

    def __init__(self) -> None:
        self.registry = CollectorRegistry()
        self._children: dict[tuple[int, tuple[str, ...]], Any] = {}
        registry = self.registry
        self.sessions = Gauge(
            "lipstream_sessions",
            "Open WebSocket sessions (connections).",
            registry=registry,
            multiprocess_mode="livesum",
        )
        self.requests_active = Gauge(
            "lipstream_requests_active",
            "Requests between ready and done.",
            registry=registry,
            multiprocess_mode="livesum",
        )
        self.draining = Gauge(
            "lipstream_draining",
            "1 while the process (with several workers: any worker) drains for shutdown.",
            registry=registry,
            multiprocess_mode="livemax",
        )
        self.loop_lag = Gauge(
            "lipstream_event_loop_lag_seconds",
            "Median event-loop lag over the last second (with several workers: the worst).",
            registry=registry,
            multiprocess_mode="livemax",
        )
        self.loop_busy = Gauge(
            "lipstream_event_loop_busy_ratio",
            "Fraction of one core the event loop used over the last second (the worst worker).",
            registry=registry,
            multiprocess_mode="livemax",
        )
        self.resident_memory = Gauge(
            "lipstream_resident_memory_bytes",
            "Resident memory of the server (summed over the workers).",
            registry=registry,
            multiprocess_mode="livesum",
        )
        self.memory_ceiling = Gauge(
            "lipstream_memory_ceiling_bytes",
            "The memory ceiling above which new work is refused (summed over the workers).",
            registry=registry,
            multiprocess_mode="livesum",
        )
        self.answer_bytes = Gauge(
            "lipstream_rest_answer_bytes",
            "Bytes held for POST /v1/synthesize answers still being sent "
            "(counted toward the memory ceiling; summed over the workers).",
            registry=registry,
            multiprocess_mode="livesum",
        )
        self.input_held = Gauge(
            "lipstream_input_held_bytes",
            "Audio input the requests hold: speech features and windows of samples, as "
            "counted against LIPSTREAM_MAX_INPUT_MB (summed over the workers).",
            registry=registry,
            multiprocess_mode="livesum",
        )
        self.input_held_peak = Gauge(
            "lipstream_input_held_peak_bytes",
            "The most audio input the requests of one worker held at once.",
            registry=registry,
            multiprocess_mode="livemax",
        )
        self.requests = Counter(
            "lipstream_requests",
            "Finished requests by how they ended (end, cancel, interrupt, error).",
            ["engine", "outcome"],
            registry=registry,
        )
        self.frames = Counter("lipstream_frames", "Frames sent.", ["engine"], registry=registry)
        self.messages = Counter(
            "lipstream_messages_received",
            "Client messages by type (invalid: rejected by the codec).",
            ["type"],
            registry=registry,
        )
        self.errors = Counter(
            "lipstream_errors", "Error messages sent, by code.", ["code"], registry=registry
        )
        self.work_stopped = Counter(
            "lipstream_work_stopped",
            "Engine calls stopped at a step by a cancel or a closed connection.",
            registry=registry,
        )
        self.refused = Counter(
            "lipstream_connections_refused",
            "WebSocket connections refused or closed by policy, by error code.",
            ["code"],
            registry=registry,
        )
        self.client_refusals = Counter(
            "lipstream_client_refusals",
            "Connections refused with too_many_client_connections (one client address over "
            "its limits), by reason: connections or upgrade_rate.",
            ["reason"],
            registry=registry,
        )
        self.recording_takes = Counter(
            "lipstream_recording_takes",
            "Recordings uploaded to /v1/recordings sessions.",
            registry=registry,
        )
        self.recording_take_bytes = Counter(
            "lipstream_recording_take_bytes",
            "Bytes of the recordings uploaded to /v1/recordings sessions.",
            registry=registry,
        )
        self.recording_jobs = Counter(
            "lipstream_recording_jobs",
            "Training jobs started for recording sessions.",
            registry=registry,
        )
        self.characters_hot_loaded = Counter(
            "lipstream_characters_hot_loaded",
            "Characters trained while serving, by outcome: served or refused.",
            ["outcome"],
            registry=registry,
        )
        self.busy_refusals = Counter(
            "lipstream_busy_refusals",
            "WebSocket sessions refused with server_busy, by reason: memory, loop_lag, "
            "loop_busy or sessions.",
            ["reason"],
            registry=registry,
        )
        self.first_frame = Histogram(
            "lipstream_first_frame_latency_seconds",
            "From receiving start to sending the first frame.",
            ["engine"],
            buckets=LATENCY_BUCKETS_S,
            registry=registry,
        )
        self.lag = Histogram(
            "lipstream_frame_lag_seconds",
            "Per frames block: from the input covering its first frame reaching the process "
            "to its send returning.",
            ["engine"],
            buckets=LATENCY_BUCKETS_S,
            registry=registry,
        )
        self.receive_lag = Histogram(
            "lipstream_receive_lag_seconds",
            "Per client WebSocket message: from its bytes reaching the process to the app "
            "taking it.",
            buckets=LATENCY_BUCKETS_S,
            registry=registry,
        )
        self.tally = StreamTally(LATENCY_BUCKETS_S)
        """The per-message metrics above (messages, frames, lag, receive lag) as the
        streaming path gathers them, folded into them by ``fold_tally``."""
        self.lane_jobs_ahead = Histogram(
            "lipstream_lane_jobs_ahead",
            "Per job of a fair lane (heavy, speech): the jobs that started in that lane "
            "between its submission and its own start, by lane and source (stream: a "
            "WebSocket connection, rest: a REST client).",
            ["lane", "source"],
            buckets=JOBS_AHEAD_BUCKETS,
            registry=registry,
        )
        self.synthesize = Histogram(
            "lipstream_synthesize_seconds",
            "Duration of POST /v1/synthesize.",
            buckets=LATENCY_BUCKETS_S,
            registry=registry,
        )

    def fold_tally(self) -> None:
        """Add what the streaming path gathered in ``tally`` to the metrics (on the event
        loop's thread, as the tally is kept)."""
        labelled = self.labelled
        self.tally.fold(
            lambda kind: labelled(self.messages, kind),
            lambda engine: labelled(self.frames, engine),
            lambda engine: labelled(self.lag, engine),
            self.receive_lag,
        )

    def observe_load(self, load: LoadSample) -> None:
        """Publish a load sample and fold the tally (the load monitor calls this on every
        tick)."""
        self.fold_tally()
        self.loop_lag.set(load.lag_ms / 1000.0)
        self.loop_busy.set(load.loop_busy)
        self.resident_memory.set(load.rss_mb * MIB)

    def observe_input(self, held: int, peak: int) -> None:
        """Publish what the requests hold of their input (``held_input``), as it changes."""
        self.input_held.set(held)
        self.input_held_peak.set(peak)

    def labelled(self, metric: MetricWrapperBase, *values: str) -> Any:
        """``metric.labels(*values)``, cached: the hot path avoids the label lookup."""
        key = (id(metric), values)
        child = self._children.get(key)
        if child is None:
            child = self._children[key] = metric.labels(*values)
        return child

    def render(self) -> tuple[bytes, str]:
        """The exposition text and its content type: with a multiprocess directory, the sum
        over every worker's files; else this process's registry (either with this process's
        tally folded in first)."""
        self.fold_tally()
        directory = multiprocess_dir()
        if directory is None:
            return generate_latest(self.registry), CONTENT_TYPE_LATEST
        forget_dead_processes(directory)
        combined = CollectorRegistry()
        MultiProcessCollector(combined, path=str(directory))  # type: ignore[no-untyped-call]
        return generate_latest(combined), CONTENT_TYPE_LATEST


def multiprocess_dir() -> Path | None:
    """``PROMETHEUS_MULTIPROC_DIR``, or None when metrics stay in the process."""
    value = os.environ.get(MULTIPROCESS_ENV)
    return Path(value) if value else None


def forget_this_process() -> None:
    """Drop this process's live gauges from the shared sum (when it stops serving)."""
    directory = multiprocess_dir()
    if directory is not None:
        mark_process_dead(os.getpid(), str(directory))  # type: ignore[no-untyped-call]


def forget_dead_processes(directory: Path) -> None:
    """Drop the live gauges of processes that no longer exist (killed or crashed workers
    never ran ``forget_this_process``; their sessions would count forever)."""
    for path in directory.glob(LIVE_GAUGE_FILES):
        pid = path.stem.rsplit("_", 1)[-1]
        if pid.isdigit() and not _running(int(pid)):
            mark_process_dead(int(pid), str(directory))  # type: ignore[no-untyped-call]


def _running(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # exists, owned by someone else
    return not _zombie(pid)


def _zombie(pid: int) -> bool:
    """Whether ``pid`` has exited but is not yet reaped: signal 0 still reaches a zombie,
    and the supervisor reaps a killed worker only when it next looks (Linux's /proc)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rpartition(")")[2].split()[:1] == ["Z"]


@contextmanager
def multiprocess_directory(workers: int) -> Iterator[Path | None]:
    """Prepare the multiprocess directory before the workers start, for the block's length.

    A ``PROMETHEUS_MULTIPROC_DIR`` that is set is created if missing and emptied of its
    ``*.db`` files (values of an earlier run would add to this one's). Unset, with
    ``workers`` > 1, a private temporary directory is made, exported for the workers
    (which inherit the environment) and removed afterwards. Unset with one worker: None,
    the metrics stay in the process."""
    given = multiprocess_dir()
    if given is not None:
        given.mkdir(parents=True, exist_ok=True)
        for stale in given.glob("*.db"):
            stale.unlink(missing_ok=True)
        yield given
        return
    if workers <= 1:
        yield None
        return
    private = Path(tempfile.mkdtemp(prefix="lipstream-metrics-"))
    os.environ[MULTIPROCESS_ENV] = str(private)
    try:
        yield private
    finally:
        os.environ.pop(MULTIPROCESS_ENV, None)
        shutil.rmtree(private, ignore_errors=True)
