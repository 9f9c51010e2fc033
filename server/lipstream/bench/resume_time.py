"""How long a client takes to resume after its worker is killed, and how many frames it loses.

Method: ``lipstream serve --workers 2`` runs on loopback with a private
prometheus directory, whose per-process gauge files say which worker holds
a session. For each of ``--utterances`` utterances (a synthetic 3 s line at
60 fps), a client with a ``ResumePolicy`` sends the first half of the
phonemes, waits for its first frames, and the worker holding the session is
SIGKILLed (uvicorn's supervisor starts a new one in its place, and the next
utterance waits until it has started, so that two workers serve each one).
The resume time runs from the kill to the arrival of the resumed request's
``ready`` (the connection is open again, on the surviving worker, and the
server has replayed the input); the client then sends the rest and ``end``.
Frames lost are the frame indices of the uninterrupted timeline
(``done.stats.frames``) that never arrived, and duplicates those that
arrived twice; both should be 0.

    python -m lipstream.bench.resume_time --models DIR [--utterances 20] [--json out.json]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import signal
import statistics
import tempfile
import time
from pathlib import Path

from prometheus_client.multiprocess import MultiProcessCollector

from lipstream_client import AsyncClient, Frames, Ready, ResumePolicy, ServerMessage

from ..loadtest.stats import percentile
from ..results_file import recorded, script_command, write_results
from .serving import Served, serving

FPS = 60.0
LINE = ["sil", "HH", "AH", "L", "OW", "W", "ER", "L", "D", "sil"] * 3
PHONEME_S = 0.1
SESSION_WAIT_S = 30.0
RESUME_WAIT_S = 60.0


def sessions_by_pid(directory: Path) -> dict[int, float]:
    """Open sessions of each live worker, from its own prometheus gauge file."""
    found: dict[int, float] = {}
    for path in directory.glob("gauge_livesum_*.db"):
        pid = int(path.stem.rsplit("_", 1)[1])
        if not Path(f"/proc/{pid}").exists():
            continue  # a killed worker's file, until a scrape removes it
        merged = MultiProcessCollector.merge([str(path)], accumulate=True)  # type: ignore[no-untyped-call]
        found[pid] = sum(
            sample.value
            for metric in merged
            for sample in metric.samples
            if sample.name == "lipstream_sessions"
        )
    return found


async def holder(directory: Path) -> int:
    """The pid of the one worker holding a session, once the gauge files show it."""
    deadline = time.monotonic() + SESSION_WAIT_S
    while time.monotonic() < deadline:
        holding = [pid for pid, n in sessions_by_pid(directory).items() if n >= 1]
        if len(holding) == 1 and sum(sessions_by_pid(directory).values()) == 1:
            return holding[0]
        await asyncio.sleep(0.02)
    raise RuntimeError("no worker showed the session in its gauge file")


async def one_utterance(url: str, directory: Path) -> tuple[float, int, int]:
    """(resume time in s, frames lost, frames duplicated) for one killed worker."""
    spans = [(label, i * PHONEME_S, (i + 1) * PHONEME_S) for i, label in enumerate(LINE)]
    readies: list[float] = []

    def tap(message: ServerMessage, received_at: float) -> None:
        if isinstance(message, Ready):
            readies.append(received_at)

    policy = ResumePolicy(attempts=40, backoff_s=0.01, max_backoff_s=0.5)
    async with AsyncClient(url, on_message=tap, resume=policy) as client:
        stream = await client.start("viseme-lerp", "demo", fps=FPS)
        half = len(spans) // 2
        await stream.send_phonemes(spans[:half])
        first = await stream.next_block()
        blocks: list[Frames] = [first] if first is not None else []
        os.kill(await holder(directory), signal.SIGKILL)
        killed_at = time.perf_counter()
        deadline = time.monotonic() + RESUME_WAIT_S
        while len(readies) < 2 and not stream.is_over and time.monotonic() < deadline:
            await asyncio.sleep(0.001)
        if len(readies) < 2:
            raise RuntimeError(f"the request did not resume within {RESUME_WAIT_S} s")
        await stream.send_phonemes(spans[half:])
        await stream.end()
        result = await stream.collect()
    blocks += result.frames
    indices = [index for block in blocks for index in range(block.first_frame, block.end_frame)]
    expected = set(range(result.done.stats.frames))
    lost = len(expected - set(indices))
    return readies[1] - killed_at, lost, len(indices) - len(set(indices))


async def run(served: Served, directory: Path, utterances: int) -> list[tuple[float, int, int]]:
    results = []
    for killed in range(1, utterances + 1):
        results.append(await one_utterance(served.ws, directory))
        # Two workers again before the next kill: the supervisor's replacement has started.
        while served.workers_started() < 2 + killed:
            await asyncio.sleep(0.1)
    return results


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--models", type=Path, required=True)
    parser.add_argument("--utterances", type=int, default=20)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as directory:
        with serving(args.models, 2, {"PROMETHEUS_MULTIPROC_DIR": directory}) as served:
            results = asyncio.run(run(served, Path(directory), args.utterances))
    times_ms = [1000.0 * seconds for seconds, _, _ in results]
    summary = {
        "utterances": len(results),
        "resume_ms_p50": statistics.median(times_ms),
        "resume_ms_p99": percentile(sorted(times_ms), 99.0),
        "resume_ms_max": max(times_ms),
        "frames_lost": sum(lost for _, lost, _ in results),
        "frames_duplicated": sum(duplicated for _, _, duplicated in results),
    }
    print(json.dumps(summary, indent=2))
    if args.json is not None:
        command = script_command("lipstream.bench.resume_time", argv)
        write_results({**recorded(command), **summary, "resume_ms": times_ms}, args.json)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
