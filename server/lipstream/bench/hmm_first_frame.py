"""First-frame latency of an audio-only ``hmm`` request over a real WebSocket, per rung.

Method: ``lipstream serve`` runs on loopback with the ``hmm`` model alone
(``serving``, one worker). For each rung of the model's fidelity ladder the
client SDK opens a connection and starts a request with ``drive: audio`` and
the rung's own engine options (``lag_ms``, ``window_ms``), waits for
``ready``, then sends a held-out line's speech as 10 ms ``audio`` chunks (the
nearest whole number of samples) paced at real time: chunk k leaves when the
chunks before it would have finished playing, on an absolute schedule, so a
late send does not push the rest back. A reader task takes
the first ``frames`` block. Recorded per request: the wall time from sending
the first chunk to receiving that block (``first_frame_ms``), the audio sent
by then (``audio_sent_ms``), the block's first frame time, and from them how
far the audio ran past that frame (``audio_ahead_ms``), beside the rung's
``ready.lookahead_ms``. The request is then cancelled. Rungs are measured in
turn, ``--rounds`` times (after one warm-up request), so that a changing load
falls on all of them; the medians go to the JSON file.

    python -m lipstream.bench.hmm_first_frame [--models DIR] [--corpus DIR] [--rounds 5]
        [--json bench/hmm_first_frame.json]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import statistics
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lipstream_client import AsyncClient, Frames

from ..config import load_settings
from ..corpus import load_corpus
from ..engines import load_model
from ..results_file import recorded, script_command, write_results
from ..training import DEMO_CORPUS_DIR
from .serving import serving

FPS = 60.0
CHUNK_S = 0.01
FIRST_FRAME_WAIT_S = 30.0


@dataclass(frozen=True)
class FirstFrame:
    """One request's first ``frames`` block and when it came."""

    fidelity: str
    lookahead_ms: float
    first_frame_ms: float
    audio_sent_ms: float
    frame_ms: float
    audio_ahead_ms: float
    before_end: bool
    block: Frames


def pcm16_of(samples: np.ndarray) -> bytes:
    """Little-endian 16-bit PCM of float samples in [−1, 1]."""
    return bytes((np.clip(samples, -1.0, 1.0) * 32767.0).astype("<i2").tobytes())


async def first_frame(
    url: str,
    character: str,
    pcm16: bytes,
    sample_rate: int,
    options: dict[str, Any],
    *,
    fps: float = FPS,
    chunk_s: float = CHUNK_S,
) -> FirstFrame:
    """Stream ``pcm16`` as real-time paced chunks to an audio-only ``hmm`` request with
    ``options`` until its first ``frames`` block arrives (or the audio runs out; then
    ``end``), then cancel it."""
    samples_per_chunk = max(1, round(chunk_s * sample_rate))
    step, pace = 2 * samples_per_chunk, samples_per_chunk / sample_rate  # bytes, seconds
    async with AsyncClient(url, open_timeout=60) as client:
        stream = await client.start(
            "hmm", character, fps=fps, options={**options, "drive": "audio"}, id="first-frame"
        )
        ready = await stream.ready()
        arrival = asyncio.get_running_loop().create_future()

        async def read() -> None:
            block = await stream.next_block()
            arrival.set_result((time.perf_counter(), block))

        reader = asyncio.create_task(read())
        started = time.perf_counter()
        sent = 0
        for index, first in enumerate(range(0, len(pcm16), step)):
            delay = started + index * pace - time.perf_counter()
            if delay > 0:
                await asyncio.wait([reader], timeout=delay)
            if arrival.done():
                break
            await stream.send_audio(pcm16[first : first + step], sample_rate)
            sent = min(len(pcm16), first + step)
        before_end = arrival.done()
        if not before_end:
            await stream.end()
        received_at, block = await asyncio.wait_for(arrival, FIRST_FRAME_WAIT_S)
        reader.cancel()
        if block is None:
            raise RuntimeError("the request ended without a frames block")
        if not stream.is_over:
            await stream.cancel()
            await asyncio.wait_for(stream.done(), FIRST_FRAME_WAIT_S)
    audio_sent_ms = 1000.0 * (sent // 2) / sample_rate
    frame_ms = 1000.0 * block.first_frame / block.fps
    return FirstFrame(
        fidelity=ready.fidelity,
        lookahead_ms=ready.lookahead_ms,
        first_frame_ms=1000.0 * (received_at - started),
        audio_sent_ms=audio_sent_ms,
        frame_ms=frame_ms,
        audio_ahead_ms=audio_sent_ms - frame_ms,
        before_end=before_end,
        block=block,
    )


def _rung_options(models: Path) -> dict[str, dict[str, Any]]:
    model = load_model(models / "hmm")
    return {rung.name: dict(rung.options) for rung in model.fidelity_ladder()}


async def _measure(
    url: str, character: str, pcm16: bytes, rate: int, rungs: dict[str, dict[str, Any]], rounds: int
) -> dict[str, list[FirstFrame]]:
    await first_frame(url, character, pcm16, rate, next(iter(rungs.values())))  # warm-up
    found: dict[str, list[FirstFrame]] = {name: [] for name in rungs}
    for _ in range(rounds):
        for name, options in rungs.items():
            found[name].append(await first_frame(url, character, pcm16, rate, options))
    return found


def summarize(found: dict[str, list[FirstFrame]]) -> dict[str, dict[str, Any]]:
    """Medians per rung of the timing fields, with the rung's options as ``ready`` named it."""
    summary: dict[str, dict[str, Any]] = {}
    for name, runs in found.items():
        row: dict[str, Any] = {"requests": len(runs), "lookahead_ms": runs[0].lookahead_ms}
        for key in ("first_frame_ms", "audio_sent_ms", "frame_ms", "audio_ahead_ms"):
            row[key] = statistics.median(asdict(run)[key] for run in runs)
        row["first_frame_ms_all"] = [run.first_frame_ms for run in runs]
        summary[name] = row
    return summary


def main(argv: list[str] | None = None) -> int:
    settings = load_settings()
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--models", type=Path, default=settings.demo_models_dir)
    parser.add_argument("--corpus", type=Path, default=settings.demo_dir / DEMO_CORPUS_DIR)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)
    heldout = load_corpus(args.corpus).split()[1]
    line = next(u for u in heldout.utterances if u.audio is not None)
    assert line.audio is not None
    rungs = _rung_options(args.models)
    character = load_model(args.models / "hmm").name
    with tempfile.TemporaryDirectory() as alone:
        (Path(alone) / "hmm").symlink_to((args.models / "hmm").resolve())
        with serving(Path(alone), 1) as served:
            found = asyncio.run(
                _measure(
                    served.ws,
                    character,
                    pcm16_of(line.audio.samples),
                    int(line.audio.sample_rate),
                    rungs,
                    args.rounds,
                )
            )
    report = {
        **recorded(script_command("lipstream.bench.hmm_first_frame", argv)),
        "utterance": line.stem,
        "audio_s": line.audio.duration,
        "fps": FPS,
        "chunk_ms": 1000.0 * CHUNK_S,
        "rungs": summarize(found),
    }
    print(json.dumps(report, indent=2))
    if args.json is not None:
        write_results(report, args.json)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
