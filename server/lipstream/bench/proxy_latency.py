"""The latency a proxy adds per frames block: message round trips, direct and through the proxy.

Method: one connection per URL runs one request on ``viseme-lerp``'s causal
rung (a 20 ms budget), whose frames for t are final as soon as the input
covers t, so each ``phonemes`` message is answered at once with its frames.
The client sends one 100 ms phoneme at a time and waits for its ``frames``
block: the round trip, from the send to the block's arrival, is the server's
work plus the transport. Run against the server directly and against the
same models behind a proxy (Ray Serve's, nginx), the difference of the
percentiles is what the proxy adds per block. The URLs are measured in
turn, ``--rounds`` times, so that a machine's changing load falls on both.

    python -m lipstream.bench.proxy_latency --url ws://A/v1/stream --url ws://B/v1/stream
"""

from __future__ import annotations

import argparse
import asyncio
import json
import statistics
import time

from lipstream_client import AsyncClient

from ..loadtest.stats import percentile

PHONEMES = ["HH", "AH", "L", "OW", "W", "ER", "D", "sil"]
PHONEME_S = 0.1


async def round_trips(url: str, messages: int) -> list[float]:
    """Milliseconds from each ``phonemes`` send to the arrival of its ``frames`` block."""
    times: list[float] = []
    async with AsyncClient(url, open_timeout=60) as client:
        stream = await client.start(
            "viseme-lerp", "demo", fps=60.0, latency_budget_ms=20.0, id="probe"
        )
        await stream.ready()
        for index in range(messages):
            label = PHONEMES[index % len(PHONEMES)]
            sent = time.perf_counter()
            await stream.send_phonemes([(label, index * PHONEME_S, (index + 1) * PHONEME_S)])
            await stream.next_block()
            times.append(1000.0 * (time.perf_counter() - sent))
        await stream.cancel()
        await stream.done()
    return times


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--url", action="append", required=True)
    parser.add_argument("--messages", type=int, default=100)
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args(argv)
    samples: dict[str, list[float]] = {url: [] for url in args.url}
    for _ in range(args.rounds):
        for url in args.url:
            samples[url] += asyncio.run(round_trips(url, args.messages))
    report = {
        url: {
            "blocks": len(values),
            "p50_ms": statistics.median(values),
            "p99_ms": percentile(sorted(values), 99.0),
        }
        for url, values in samples.items()
    }
    print(json.dumps(report, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
