"""Graceful shutdown: a drain finishes in-flight utterances, then closes with 1001.

In-process servers test the drain itself; ``lipstream serve`` subprocesses
test that SIGTERM reaches it, with one worker and with several.
"""

from __future__ import annotations

import asyncio
import os
import signal
import subprocess
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import httpx
import numpy as np
import pytest

from lipstream.config import ServerSettings
from lipstream.server.catalog import Catalog
from lipstream.server.lifecycle import Drainable, Lifecycle
from lipstream.server.runner import DRAIN_MARKED
from lipstream_client import Done, End, ErrorMessage, PhonemeItem, Phonemes, Ready, Start
from tests.helpers import (
    VirtualClock,
    eventually,
    free_port,
    return_frames,
    run_on_virtual_time,
    serve_command,
)
from tests.lipstream.server.harness import client, frame_rows, only_errors, serving
from tests.live_server import READY_POLLS

SPANS = [("HH", 0.0, 0.1), ("AY1", 0.1, 0.4), ("M", 0.4, 0.5), ("sil", 0.5, 0.7)]
ITEMS = tuple(PhonemeItem(*span) for span in SPANS)


def readyz(base: str) -> int:
    try:
        return httpx.get(f"{base}/readyz", timeout=2).status_code
    except httpx.TransportError:
        return 0


def test_drain_finishes_in_flight_requests_then_closes_with_1001(
    lerp_dir: Path, catalog: Catalog
) -> None:
    with serving(lerp_dir, ServerSettings(drain_timeout_s=20)) as served, client(served.ws) as ws:
        ws.send(Start("a", "viseme-lerp", "demo"), Phonemes("a", ITEMS[:2]))
        assert isinstance(ws.recv(), Ready)
        drained = served.call_soon(served.app.state.lifecycle.drain(20))
        eventually(lambda: readyz(served.http) == 503, "not ready while draining")
        assert httpx.get(f"{served.http}/healthz").status_code == 200
        with client(served.ws) as late:
            messages, code, reason = late.closed()
        assert [(m.code, m.id) for m in only_errors(messages)] == [("shutting_down", None)]
        assert (code, reason) == (1001, "shutting_down")
        ws.send(Start("b", "viseme-lerp", "demo"))
        [refused] = ws.until_done("b")
        assert isinstance(refused, ErrorMessage)
        assert (refused.code, refused.id, refused.fatal) == ("shutting_down", "b", True)
        ws.send(Phonemes("a", ITEMS[2:]), End("a"))
        answers = ws.until_done("a")
        messages, code, reason = ws.closed()
        assert drained.result(10) == 0  # nothing had to be cut off
    assert isinstance(answers[-1], Done) and answers[-1].reason == "end"
    rows = frame_rows(answers)
    expected = catalog.model("viseme-lerp", "demo").synthesize(SPANS, fps=60).frames
    assert sorted(rows) == list(range(len(expected) + return_frames(60)))
    np.testing.assert_array_equal(np.array([rows[i] for i in range(len(expected))]), expected)
    assert [(m.code, m.id, m.fatal) for m in only_errors(messages)] == [
        ("shutting_down", None, True)
    ]
    assert (code, reason) == (1001, "shutting_down")


def test_the_drain_timeout_bounds_the_wait(lerp_dir: Path) -> None:
    with serving(lerp_dir, ServerSettings(drain_timeout_s=0.3)) as served, client(served.ws) as ws:
        ws.send(Start("a", "viseme-lerp", "demo"), Phonemes("a", ITEMS[:1]))
        assert isinstance(ws.recv(), Ready)
        drained = served.call_soon(served.app.state.lifecycle.drain(0.3))
        messages, code, reason = ws.closed()
        assert drained.result(5) == 1  # one session cut off (when: the test below)
    assert (code, reason) == (1001, "shutting_down")
    assert any(isinstance(m, ErrorMessage) and m.code == "shutting_down" for m in messages)


Events = list[tuple[str, float]]


class RecordedConnection:
    """A ``Drainable`` that records when (loop time) it was asked to drain and aborted, and
    leaves ``finish_s`` after the drain began (never: None), or at once when aborted."""

    def __init__(self, lifecycle: Lifecycle, finish_s: float | None) -> None:
        self.lifecycle, self.finish_s = lifecycle, finish_s
        self.loop = asyncio.get_running_loop()
        self.events: Events = []

    def drain(self) -> None:
        self.events.append(("drain", self.loop.time()))
        if self.finish_s is not None:
            self.loop.call_later(self.finish_s, self.lifecycle.release, self)

    def abort(self) -> None:
        self.events.append(("abort", self.loop.time()))
        self.loop.call_soon(self.lifecycle.release, self)


def test_the_drain_waits_its_timeout_then_aborts_only_the_unfinished() -> None:
    async def scenario(_: VirtualClock) -> tuple[int, Events, Events, set[Drainable]]:
        lifecycle = Lifecycle(max_sessions=3)
        finishing, stuck = RecordedConnection(lifecycle, 0.2), RecordedConnection(lifecycle, None)
        assert lifecycle.admit(finishing) and lifecycle.admit(stuck)
        cut = await lifecycle.drain(0.5)
        return cut, finishing.events, stuck.events, lifecycle.connections

    cut, finishing, stuck, left = run_on_virtual_time(scenario)
    assert (cut, left) == (1, set())
    assert finishing == [("drain", 0.0)]
    assert stuck == [("drain", 0.0), ("abort", pytest.approx(0.5))]


@contextmanager
def lipstream_serve(models: Path, *flags: str) -> Iterator[tuple[subprocess.Popen[bytes], str]]:
    port = free_port()
    env = {**os.environ, "LIPSTREAM_DRAIN_TIMEOUT_S": "20", "LIPSTREAM_LOG_LEVEL": "warning"}
    process = subprocess.Popen(
        serve_command(models, port, *flags),
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    base = f"http://127.0.0.1:{port}"
    try:
        eventually(lambda: readyz(base) == 200, "ready", polls=READY_POLLS)
        yield process, base
    finally:
        if process.poll() is None:
            process.kill()
        process.wait(timeout=10)


@pytest.mark.parametrize("workers", ["1", "2"])
def test_sigterm_loses_no_in_flight_utterance(
    lerp_dir: Path, catalog: Catalog, workers: str
) -> None:
    with lipstream_serve(lerp_dir, "--workers", workers) as (process, base):
        url = base.replace("http://", "ws://") + "/v1/stream"
        with client(url) as first, client(url, "json") as second:
            for ws in (first, second):
                ws.send(Start("a", "viseme-lerp", "demo"), Phonemes("a", ITEMS[:2]))
                assert isinstance(ws.recv(), Ready)
            process.send_signal(signal.SIGTERM)
            eventually(lambda: readyz(base) in (0, 503), "not ready after SIGTERM")
            outcomes = []
            for ws in (first, second):
                ws.send(Phonemes("a", ITEMS[2:]), End("a"))
                answers = ws.until_done("a")
                outcomes.append((answers, ws.closed()))
        process.wait(timeout=15)
    expected = catalog.model("viseme-lerp", "demo").synthesize(SPANS, fps=60).frames
    for answers, (_, code, reason) in outcomes:
        rows = frame_rows(answers)
        assert sorted(rows) == list(range(len(expected) + return_frames(60)))
        np.testing.assert_array_equal(np.array([rows[i] for i in range(len(expected))]), expected)
        assert isinstance(answers[-1], Done)
        assert (code, reason) == (1001, "shutting_down")


def test_readyz_answers_503_once_the_supervisor_of_two_workers_has_the_signal(
    lerp_dir: Path,
) -> None:
    """``lipstream serve --workers 2``: uvicorn's supervisor looks at a signal only every half
    second before it passes it on, and until then each worker said ready. Now the first
    /readyz after the supervisor's mark (its log line, the ordering point) is 503, from
    whichever worker answers: a request left in flight keeps its worker serving."""
    port = free_port()
    env = {**os.environ, "LIPSTREAM_DRAIN_TIMEOUT_S": "20", "LIPSTREAM_LOG_LEVEL": "warning"}
    process = subprocess.Popen(
        serve_command(lerp_dir, port, "--workers", "2"),
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    base = f"http://127.0.0.1:{port}"
    try:
        eventually(lambda: readyz(base) == 200, "ready", polls=READY_POLLS)
        with client(base.replace("http://", "ws://") + "/v1/stream") as ws:
            ws.send(Start("a", "viseme-lerp", "demo"), Phonemes("a", ITEMS[:2]))
            assert isinstance(ws.recv(), Ready)
            process.send_signal(signal.SIGTERM)
            assert process.stderr is not None
            # Bounded: the supervisor's log ends when it exits, at the latest after the drain.
            marked = any(DRAIN_MARKED in line for line in iter(process.stderr.readline, ""))
            assert marked, "the supervisor never marked the drain"
            assert readyz(base) == 503
            ws.send(Phonemes("a", ITEMS[2:]), End("a"))
            assert isinstance(ws.until_done("a")[-1], Done)
        process.wait(timeout=30)
    finally:
        if process.poll() is None:
            process.kill()
        process.wait(timeout=10)
