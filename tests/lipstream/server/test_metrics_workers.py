"""``/metrics`` of ``lipstream serve --workers 2`` sums every worker (prometheus multiprocess).

A real server on loopback with ``PROMETHEUS_MULTIPROC_DIR`` set to a
directory holding a stale earlier run, driven by the real client SDK over
connections opened until both workers hold some. The per-pid value files
in the directory say which worker served what; ``/metrics`` (answered by
either worker) must give the exact totals the client sent and received,
open sessions summed over the live workers only (also after one is
killed), and the stale run must not count.
"""

from __future__ import annotations

import asyncio
import os
import signal
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import httpx
import pytest
from prometheus_client.parser import text_string_to_metric_families

from lipstream.engines.base import Model
from lipstream.server.metrics import MULTIPROCESS_ENV, multiprocess_directory
from lipstream_client import AsyncClient, StreamResult
from tests.helpers import eventually, return_frames
from tests.live_server import lipstream_serve, per_worker, sessions_by_worker

FPS = 60.0
LINE = [
    ("sil", 0.0, 0.1),
    ("HH", 0.1, 0.17),
    ("AH", 0.17, 0.24),
    ("L", 0.24, 0.31),
    ("OW", 0.31, 0.5),
    ("W", 0.5, 0.58),
    ("ER", 0.58, 0.72),
    ("L", 0.72, 0.8),
    ("D", 0.8, 0.86),
    ("sil", 0.86, 1.0),
]
CHUNK = 3
PHONEMES_MESSAGES = 4  # ceil(10 / 3)
REQUESTS_PER_CONNECTION = 2
MAX_CONNECTIONS = 40
STALE_FRAMES = 12345.0
STALE_RUN = (
    "from prometheus_client import Counter, Gauge\n"
    f"Counter('lipstream_frames', '', ['engine']).labels('viseme-lerp').inc({STALE_FRAMES})\n"
    "Gauge('lipstream_sessions', '', multiprocess_mode='livesum').inc(7)\n"
)
EVENTUALLY_S = 30.0
Samples = dict[tuple[str, frozenset[tuple[str, str]]], float]


def open_sessions(base: str) -> float:
    return value(scrape(base), "lipstream_sessions")


def scrape(base: str) -> Samples:
    """Every sample of ``/metrics``, by name and labels (a new connection each time)."""
    text = httpx.get(f"{base}/metrics", timeout=5).text
    return {
        (sample.name, frozenset(sample.labels.items())): sample.value
        for family in text_string_to_metric_families(text)
        for sample in family.samples
    }


def value(samples: Samples, name: str, **labels: str) -> float:
    return samples.get((name, frozenset(labels.items())), 0.0)


def frames_by_worker(directory: Path) -> dict[int, float]:
    return per_worker(directory, "counter", "lipstream_frames_total", engine="viseme-lerp")


async def request(client: AsyncClient) -> StreamResult:
    stream = await client.start("viseme-lerp", "demo", fps=FPS)
    for first in range(0, len(LINE), CHUNK):
        await stream.send_phonemes(LINE[first : first + CHUNK])
    await stream.end()
    return await asyncio.wait_for(stream.collect(), 10)


async def connect_until(
    url: str, both_workers: Callable[[], bool], requests: int, clients: list[AsyncClient]
) -> list[StreamResult]:
    """Open connections (kept in ``clients``), each serving ``requests`` requests, until
    ``both_workers()`` holds; the results of every request."""
    results: list[StreamResult] = []
    while not both_workers():
        assert len(clients) < MAX_CONNECTIONS, "every connection went to one worker"
        client = AsyncClient(url, open_timeout=10)
        await client.connect()
        clients.append(client)
        for _ in range(requests):
            results.append(await request(client))
    return results


async def close_all(clients: list[AsyncClient]) -> None:
    await asyncio.gather(*(client.close() for client in clients))


def test_metrics_of_two_workers_are_summed_exactly(
    lerp_dir: Path, trained_models: dict[str, Model], tmp_path: Path
) -> None:
    directory = tmp_path / "prometheus"
    directory.mkdir()
    subprocess.run(
        [sys.executable, "-c", STALE_RUN],
        check=True,
        timeout=30,
        env={**os.environ, MULTIPROCESS_ENV: str(directory)},
    )
    assert sum(frames_by_worker(directory).values()) == STALE_FRAMES
    spoken = len(trained_models["viseme-lerp"].synthesize(LINE, fps=FPS).frames)
    expected_frames = spoken + return_frames(FPS)

    with (
        lipstream_serve(
            lerp_dir, 2, {MULTIPROCESS_ENV: str(directory)}, tmp_path / "serve.log"
        ) as (process, base),
        asyncio.Runner() as runner,
    ):  # one loop for the clients, between blocking checks
        url = base.replace("http://", "ws://") + "/v1/stream"
        # Traffic on both workers, connections still open: sessions sum over the workers.
        clients: list[AsyncClient] = []
        results = runner.run(
            connect_until(
                url,
                lambda: len([f for f in frames_by_worker(directory).values() if f]) >= 2,
                REQUESTS_PER_CONNECTION,
                clients,
            )
        )
        open_scrapes = [scrape(base) for _ in range(4)]
        shares = sessions_by_worker(directory)
        runner.run(close_all(clients))
        eventually(lambda: open_sessions(base) == 0, "no open sessions")
        closed_scrapes = [scrape(base) for _ in range(4)]
        worker_frames = frames_by_worker(directory)

        # A killed worker's sessions leave the sum; its counts stay in the totals.
        held: list[AsyncClient] = []
        runner.run(
            connect_until(
                url,
                lambda: len([s for s in sessions_by_worker(directory).values() if s]) >= 2,
                0,
                held,
            )
        )
        eventually(
            lambda: sum(sessions_by_worker(directory).values()) == len(held),
            "held sessions in the workers' files",
        )
        holding = sessions_by_worker(directory)
        victim = max(holding, key=lambda pid: holding[pid])
        survivor = next(pid for pid in holding if pid != victim and holding[pid])
        os.kill(victim, signal.SIGKILL)
        survivors = len(held) - holding[victim]
        # The sum drops a worker's live gauges once its process is gone: after uvicorn's
        # supervisor (every 0.5 s, slower on a busy machine) has reaped it. A bound on an
        # eventual state, not a speed.
        eventually(
            lambda: open_sessions(base) == survivors,
            f"open sessions after killing a worker that held {holding[victim]:g}",
        )
        after_kill = scrape(base)
        runner.run(close_all(held))
        eventually(lambda: open_sessions(base) == 0, "no open sessions")
        process.terminate()
        process.wait(timeout=60)  # a bound for a busy machine, not a speed

    requests = len(results)
    assert requests == REQUESTS_PER_CONNECTION * len(clients)
    assert [r.done.stats.frames for r in results] == [expected_frames] * requests
    assert all(r.done.reason == "end" for r in results)
    frames = requests * expected_frames

    # While open: every scrape, whichever worker answered, counts every session.
    assert len(shares) == 2 and all(0 < share < len(clients) for share in shares.values())
    assert sum(shares.values()) == len(clients)
    for samples in open_scrapes:
        assert value(samples, "lipstream_sessions") == len(clients)
    # After: exact totals over both workers, none of the stale run's.
    assert len([f for f in worker_frames.values() if f]) == 2
    assert sum(worker_frames.values()) == frames
    for samples in closed_scrapes:
        assert value(samples, "lipstream_sessions") == 0
        assert value(samples, "lipstream_requests_active") == 0
        assert value(samples, "lipstream_draining") == 0
        assert value(samples, "lipstream_frames_total", engine="viseme-lerp") == frames
        assert (
            value(samples, "lipstream_requests_total", engine="viseme-lerp", outcome="end")
            == requests
        )
        assert value(samples, "lipstream_messages_received_total", type="start") == requests
        assert (
            value(samples, "lipstream_messages_received_total", type="phonemes")
            == requests * PHONEMES_MESSAGES
        )
        assert value(samples, "lipstream_messages_received_total", type="end") == requests
        assert (
            value(samples, "lipstream_first_frame_latency_seconds_count", engine="viseme-lerp")
            == requests
        )
    assert value(after_kill, "lipstream_frames_total", engine="viseme-lerp") == frames
    # The killed worker's live gauges were dropped; the survivor took its own when it stopped.
    assert list(directory.glob(f"gauge_live*_{victim}.db")) == []
    assert list(directory.glob(f"gauge_live*_{survivor}.db")) == []


def test_the_multiprocess_directory_is_emptied_or_made_private(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    given = tmp_path / "given"
    given.mkdir()
    (given / "counter_1.db").write_bytes(b"stale")
    (given / "notes.txt").write_text("not ours")
    monkeypatch.setenv(MULTIPROCESS_ENV, str(given))
    with multiprocess_directory(workers=2) as directory:
        assert directory == given
        assert sorted(p.name for p in given.iterdir()) == ["notes.txt"]
    assert given.is_dir() and os.environ[MULTIPROCESS_ENV] == str(given)

    monkeypatch.delenv(MULTIPROCESS_ENV)
    with multiprocess_directory(workers=1) as directory:
        assert directory is None and MULTIPROCESS_ENV not in os.environ
    with multiprocess_directory(workers=3) as directory:
        assert directory is not None and directory.is_dir() and not any(directory.iterdir())
        assert os.environ[MULTIPROCESS_ENV] == str(directory)
        private = directory
    assert not private.exists() and MULTIPROCESS_ENV not in os.environ


def test_several_workers_without_a_directory_get_a_private_one(
    lerp_dir: Path, tmp_path: Path
) -> None:
    temporary = tmp_path / "tmp"
    temporary.mkdir()
    environ = {"TMPDIR": str(temporary)}
    with (
        lipstream_serve(lerp_dir, 2, environ, tmp_path / "serve.log") as (process, base),
        asyncio.Runner() as runner,
    ):
        url = base.replace("http://", "ws://") + "/v1/stream"
        [directory] = temporary.glob("lipstream-metrics-*")
        clients: list[AsyncClient] = []
        runner.run(
            connect_until(
                url,
                lambda: len([s for s in sessions_by_worker(directory).values() if s]) >= 2,
                0,
                clients,
            )
        )
        eventually(
            lambda: sum(sessions_by_worker(directory).values()) == len(clients),
            "sessions in the workers' files",
        )
        scrapes = [scrape(base) for _ in range(4)]
        runner.run(close_all(clients))
        process.terminate()
        process.wait(timeout=60)  # a bound for a busy machine, not a speed
    assert [value(samples, "lipstream_sessions") for samples in scrapes] == [len(clients)] * 4
    assert not directory.exists()


def test_a_killed_worker_not_yet_reaped_counts_as_gone() -> None:
    from lipstream.server.metrics import _running

    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        assert _running(child.pid)
        os.kill(child.pid, signal.SIGKILL)
        # a zombie until reaped below: signal 0 still reaches it
        eventually(lambda: not _running(child.pid), "the killed child counts as gone")
    finally:
        child.wait(timeout=EVENTUALLY_S)
    assert not _running(child.pid)
