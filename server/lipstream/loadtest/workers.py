"""Spreading one clip's load over several processes, and gathering what they measured.

Sketch: one Python process drives at most one core, and a load generator
near its limit delays the frames it timestamps, inflating the very lag it
measures. With ``workers`` > 1 the parent forks that many processes per
clip length. Worker w takes the request indices w, w + workers, ... and its
share of the sessions, runs them on its own event loop and writes its
``ClipShare`` back through a pipe: a JSON header (records, probe results,
CPU seconds) and the raw bytes of the two block arrays, so nothing is
pickled. Meanwhile the parent runs the first-frame probe, if asked, until
every worker has reported. Forking happens outside any event loop, and
multiprocessing ends the children with ``os._exit``, so nothing inherited
from the parent runs twice.
"""

from __future__ import annotations

import json
import multiprocessing
from array import array
from dataclasses import asdict
from multiprocessing.connection import Connection
from typing import Any

from ..errors import LipstreamError
from .sessions import ClipPlan, ClipShare, RequestRecord, run_coroutine, run_share


class WorkerFailed(LipstreamError):
    code = "loadtest_worker_failed"


def split(total: int, parts: int, part: int) -> int:
    """Part ``part`` of ``total`` items shared as evenly as possible among ``parts``."""
    return total // parts + (1 if part < total % parts else 0)


def encode_share(share: ClipShare) -> tuple[bytes, bytes, bytes]:
    """(JSON header, block lags as float64, block frame counts as int64)."""
    header = {
        "records": [asdict(record) for record in share.records],
        "probe_ms": share.probe_ms,
        "session_spans": share.session_spans,
        "probe_errors": share.probe_errors,
        "cpu_s": share.cpu_s,
    }
    return (
        json.dumps(header).encode("utf-8"),
        share.block_lag_ms.tobytes(),
        share.block_frames.tobytes(),
    )


def decode_share(header: bytes, lags: bytes, frames: bytes) -> ClipShare:
    """The inverse of ``encode_share``."""
    fields: dict[str, Any] = json.loads(header)
    block_lag_ms: array[float] = array("d")
    block_lag_ms.frombytes(lags)
    block_frames: array[int] = array("q")
    block_frames.frombytes(frames)
    return ClipShare(
        records=[RequestRecord(**record) for record in fields["records"]],
        block_lag_ms=block_lag_ms,
        block_frames=block_frames,
        probe_ms=list(fields["probe_ms"]),
        session_spans=[(start, end) for start, end in fields["session_spans"]],
        probe_errors=list(fields["probe_errors"]),
        cpu_s=float(fields["cpu_s"]),
    )


def _worker(
    plan: ClipPlan, requests: int, sessions: int, workers: int, part: int, pipe: Connection
) -> None:
    indices = list(range(part, requests, workers))
    share = run_coroutine(run_share(plan, indices, split(sessions, workers, part), False))
    for chunk in encode_share(share):
        pipe.send_bytes(chunk)
    pipe.close()


def run_in_workers(
    plan: ClipPlan, requests: int, sessions: int, workers: int, probe: bool
) -> ClipShare:
    """Run the clip's ``requests`` over ``sessions`` sessions in ``workers`` forked
    processes (and the probe in this one); their merged measurements."""
    context = multiprocessing.get_context("fork")
    pipes: list[Connection] = []
    processes = []
    for part in range(workers):
        receiving, sending = context.Pipe(duplex=False)
        process = context.Process(
            target=_worker,
            name=f"lipstream-loadtest-{part}",
            args=(plan, requests, sessions, workers, part, sending),
        )
        process.start()
        sending.close()
        pipes.append(receiving)
        processes.append(process)
    merged = ClipShare()
    if probe:
        merged.extend(
            run_coroutine(run_share(plan, [], 0, True, lambda: not all(p.poll() for p in pipes)))
        )
    try:
        for part, pipe in enumerate(pipes):
            try:
                merged.extend(decode_share(*(pipe.recv_bytes() for _ in range(3))))
            except EOFError:
                raise WorkerFailed(
                    f"load-generating process {part} ended without results "
                    f"(exit code {processes[part].exitcode})"
                ) from None
    finally:
        for process in processes:
            process.join()
    return merged
