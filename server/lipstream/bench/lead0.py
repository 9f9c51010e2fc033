"""Frame lag and first-frame latency at lead 0, over the wire, for every rung of every engine.

Method: against a running server (a loopback ``ws://`` URL), for each engine
of the character and each rung of its ladder (read from the models directory
the server serves), one connection runs one request at a time, so the server
is otherwise idle:

* ``requests`` requests stream a synthetic clip (``loadtest.clips``), each
  phoneme sent at its start time (lead 0, as a voice pipeline sends them), with
  the rung's engine options and no budget. Each frame's lag is its block's
  arrival minus the frame's scheduled time (``start`` sent + index / fps), as
  the load generator measures it; a causal rung's frames of a span arrive with
  the span, at its start, so their lags are negative down to minus the span's
  length.
* ``probes`` requests of 30 phonemes sent whole in one message time their
  first frame: from sending ``start`` to the first ``frames`` block.

Reported per rung: the lookahead ``ready`` reported for the rung's options, frame lag
p50 and p99 and first-frame latency p50 and p99, in ms.

    python -m lipstream.bench.lead0 --url ws://127.0.0.1:8000/v1/stream --models DIR
        [--character demo] [--engine NAME ...] [--clip 10] [--requests 2] [--probes 20]
        [--json out.json]

``--json`` writes the rows (``rows``) after the command, date and machine.
"""

from __future__ import annotations

import argparse
import asyncio
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

from lipstream_client import AsyncClient, Frames, ServerMessage, Stream

from ..engines.base import Rung
from ..loadtest.clips import Span, synthetic_clip
from ..models import ModelRegistry
from ..results_file import recorded, script_command, write_results
from ..server.session import json_value

FPS = 60.0
PROBE_PHONEMES = 30
PROBE_PHONEME_S = 0.08
_MS = 1000.0


@dataclass(frozen=True)
class Lead0Row:
    """One rung's lag and first-frame latency at lead 0, ms."""

    engine: str
    rung: str
    lookahead_ms: float
    frames: int
    lag_p50_ms: float
    lag_p99_ms: float
    first_frame_p50_ms: float
    first_frame_p99_ms: float


class _Tap:
    """Arrival times of the frames of the request being measured."""

    def __init__(self) -> None:
        self.request_id = ""
        self.sent_at = 0.0
        self.lags_ms: list[float] = []
        self.first_at: float | None = None

    def begin(self, request_id: str) -> None:
        self.request_id, self.sent_at, self.first_at = request_id, time.perf_counter(), None

    def __call__(self, message: ServerMessage, received_at: float) -> None:
        if not isinstance(message, Frames) or message.id != self.request_id:
            return
        if self.first_at is None:
            self.first_at = received_at
        for index in range(message.first_frame, message.end_frame):
            self.lags_ms.append((received_at - self.sent_at - index / message.fps) * _MS)


async def _start(
    client: AsyncClient, tap: _Tap, engine: str, character: str, rung: Rung, request_id: str
) -> Stream:
    """Start a request at ``rung`` (its options, no budget), its frames timed from now."""
    tap.begin(request_id)
    options = {key: json_value(value) for key, value in rung.options.items()}
    return await client.start(engine, character, id=request_id, fps=FPS, options=options)


async def _paced(
    client: AsyncClient,
    tap: _Tap,
    engine: str,
    character: str,
    rung: Rung,
    spans: Sequence[Span],
    request_id: str,
) -> float:
    """Stream ``spans`` at lead 0; the lookahead ``ready`` reported (ms)."""
    stream = await _start(client, tap, engine, character, rung, request_id)
    for label, start, end in spans:
        delay = tap.sent_at + start - time.perf_counter()
        if delay > 0:
            await asyncio.sleep(delay)
        await stream.send_phonemes([(label, start, end)])
        stream.poll()
    await stream.end()
    await stream.done()
    return (await stream.ready()).lookahead_ms


async def _probe(
    client: AsyncClient, tap: _Tap, engine: str, character: str, rung: Rung, request_id: str
) -> float:
    """First-frame latency (ms) of 30 phonemes sent whole."""
    labels = [label for label, _, _ in synthetic_clip(10.0, seed=7) if label != "sil"]
    items = [
        (labels[k % len(labels)], k * PROBE_PHONEME_S, (k + 1) * PROBE_PHONEME_S)
        for k in range(PROBE_PHONEMES)
    ]
    stream = await _start(client, tap, engine, character, rung, request_id)
    await stream.send_phonemes(items)
    await stream.end()
    await stream.done()
    if tap.first_at is None:
        raise RuntimeError(f"{engine} at rung {rung.name} sent no frames for {request_id}")
    return (tap.first_at - tap.sent_at) * _MS


def _quantile(values: Sequence[float], q: float) -> float:
    ordered = sorted(values)
    return round(ordered[min(len(ordered) - 1, int(q * (len(ordered) - 1) + 0.5))], 1)


async def measure_rung(
    url: str, engine: str, character: str, rung: Rung, clip_s: float, requests: int, probes: int
) -> Lead0Row:
    """``Lead0Row`` of one rung, on a fresh connection."""
    tap = _Tap()
    client = AsyncClient(url, on_message=tap)
    await client.connect()
    try:
        lookahead_ms = 0.0
        for index in range(requests):
            spans = synthetic_clip(clip_s, seed=index)
            lookahead_ms = await _paced(
                client, tap, engine, character, rung, spans, f"paced-{index}"
            )
        lags = list(tap.lags_ms)
        firsts = [
            await _probe(client, tap, engine, character, rung, f"probe-{index}")
            for index in range(probes)
        ]
    finally:
        await client.close()
    return Lead0Row(
        engine,
        rung.name,
        round(lookahead_ms, 1),
        len(lags),
        _quantile(lags, 0.5),
        _quantile(lags, 0.99),
        _quantile(firsts, 0.5),
        _quantile(firsts, 0.99),
    )


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--url", required=True, help="ws:// URL of the server's /v1/stream")
    parser.add_argument("--models", type=Path, required=True, help="the server's model directory")
    parser.add_argument("--character", default="demo", help="character name")
    parser.add_argument("--engine", action="append", help="engine (repeatable; default all)")
    parser.add_argument("--clip", type=float, default=10.0, help="clip length, s")
    parser.add_argument("--requests", type=int, default=2, help="paced requests per rung")
    parser.add_argument("--probes", type=int, default=20, help="first-frame probes per rung")
    parser.add_argument("--json", type=Path, help="write the rows here")
    args = parser.parse_args(argv)
    registry = ModelRegistry.load(args.models)
    rows = []
    for name in args.engine or registry.characters().get(args.character, []):
        for rung in registry.find(name, args.character).fidelity_ladder():
            row = asyncio.run(
                measure_rung(
                    args.url, name, args.character, rung, args.clip, args.requests, args.probes
                )
            )
            rows.append(row)
            print(
                f"{row.engine:14s} {row.rung:16s} lag p50 {row.lag_p50_ms:7.1f} p99 "
                f"{row.lag_p99_ms:7.1f} ms   first frame p50 {row.first_frame_p50_ms:6.1f} "
                f"p99 {row.first_frame_p99_ms:6.1f} ms"
            )
    if args.json is not None:
        command = script_command("lipstream.bench.lead0", argv)
        write_results({**recorded(command), "rows": [asdict(row) for row in rows]}, args.json)


if __name__ == "__main__":
    main()
