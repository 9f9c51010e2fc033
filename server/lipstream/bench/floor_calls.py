"""CPU per streaming call at the latency floor: what a session costs the server's engine.

Method: at lead 0 a session sends one ``phonemes`` message per phoneme and the
server calls its synthesizer's ``feed([span])`` then ``frames()`` once per
message, at the engine's ``causal`` rung. For each engine, ``passes`` fresh
requests (60 fps) are fed ``calls`` phonemes of 80 ms each, one per call, as
client-sent tuples of stressed ARPAbet labels, after one unmeasured warm-up
request (compiled kernels, caches); each call's CPU time is read on the
measuring thread's clock (``time.thread_time``), so other processes on a shared
machine lengthen it only through cache and frequency effects. Reported: the
median, mean and 90th percentile per call, in µs; the mean is what a session
costs the server's core. ``--all-rungs`` measures every rung of each engine's
ladder the same way, its phonemes fed one per call as a client sending them
ahead of time would.

    python -m lipstream.bench.floor_calls --models DIR [--character demo]
        [--engine NAME ...] [--all-rungs] [--calls 200] [--passes 3] [--json out.json]

``--json`` writes the rows (``rows``) after the command, date and machine.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

from ..engines.base import Model, Rung, make_request
from ..models import ModelRegistry
from ..results_file import recorded, script_command, write_results

LABELS = tuple("HH AH0 L OW1 W ER1 L D sil M AA1 P B IY1 S T".split())
PHONEME_S = 0.08
FPS = 60.0


@dataclass(frozen=True)
class FloorCost:
    """One engine's CPU per feed+frames call at one rung (by default its causal one), µs."""

    engine: str
    calls: int
    median_us: float
    p90_us: float
    mean_us: float = 0.0
    rung: str = "causal"


def causal_rung(model: Model) -> Rung:
    return next(rung for rung in model.fidelity_ladder() if rung.name == "causal")


def call_costs(model: Model, calls: int, rung: Rung | None = None) -> list[float]:
    """CPU seconds of each of ``calls`` feed+frames calls of one request at ``rung``
    (default: the causal one)."""
    rung = rung or causal_rung(model)
    synthesizer = model.start(make_request(FPS, **rung.options))
    costs, t = [], 0.0
    for index in range(calls):
        span = (LABELS[index % len(LABELS)], t, t + PHONEME_S)
        started = time.thread_time()
        synthesizer.feed([span])
        synthesizer.frames()
        costs.append(time.thread_time() - started)
        t += PHONEME_S
    return costs


def measure(model: Model, calls: int = 200, passes: int = 3, rung: Rung | None = None) -> FloorCost:
    """The engine's ``FloorCost`` at ``rung`` (default: causal) over ``passes`` requests,
    after one warm-up request."""
    rung = rung or causal_rung(model)
    call_costs(model, min(calls, 50), rung)
    costs = sorted(cost for _ in range(passes) for cost in call_costs(model, calls, rung))
    return FloorCost(
        model.engine,
        len(costs),
        round(1e6 * statistics.median(costs), 1),
        round(1e6 * costs[int(0.9 * (len(costs) - 1))], 1),
        round(1e6 * statistics.fmean(costs), 1),
        rung.name,
    )


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--models", type=Path, required=True, help="model directory")
    parser.add_argument("--character", default="demo", help="character name")
    parser.add_argument("--engine", action="append", help="engine (repeatable; default all)")
    parser.add_argument("--calls", type=int, default=200, help="calls per request")
    parser.add_argument("--passes", type=int, default=3, help="requests per engine and rung")
    parser.add_argument(
        "--all-rungs", action="store_true", help="every rung of the ladder, not only causal"
    )
    parser.add_argument("--json", type=Path, help="write the rows here")
    args = parser.parse_args(argv)
    registry = ModelRegistry.load(args.models)
    names = args.engine or registry.characters().get(args.character, [])
    rows = []
    for name in names:
        model = registry.find(name, args.character)
        for rung in model.fidelity_ladder() if args.all_rungs else [causal_rung(model)]:
            row = measure(model, args.calls, args.passes, rung)
            rows.append(row)
            print(
                f"{row.engine:15s} {row.rung:18s} median {row.median_us:8.1f} µs   "
                f"mean {row.mean_us:8.1f} µs   p90 {row.p90_us:8.1f} µs"
            )
    if args.json is not None:
        command = script_command("lipstream.bench.floor_calls", argv)
        write_results({**recorded(command), "rows": [asdict(row) for row in rows]}, args.json)


if __name__ == "__main__":
    main()
