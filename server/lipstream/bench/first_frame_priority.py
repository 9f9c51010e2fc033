"""A whole request's first frame beside steady streaming load, on two servers side by side.

Method: two servers run on this machine (``--before`` and ``--after``: the same models,
two trees of the code). For each engine and round, ``lipstream loadtest`` runs against
each server in turn (the order alternates between rounds, so drift of the machine falls on
both): ``streams`` causal sessions (phonemes sent at their start, ``lead_ms`` 0, a
``latency_budget_ms``) streaming one ``clip_s`` clip each, and, on one more connection,
requests of ``probe_phonemes`` phonemes sent whole, one after another, each timed from
sending ``start`` to its first ``frames`` block (the load test's probe). Each server first
streams ``WARMUP_STREAMS`` sessions of each engine, unmeasured: the first load after start-up
loads kernels and fills caches, and measured seconds of lag. Reported per
engine, server and round: the probe's first-frame p50, p99 and max and its request count,
the sessions' frame lag p50 and p99, the peak of sessions held at once and the errors.

    python -m lipstream.bench.first_frame_priority --before ws://127.0.0.1:8822/v1/stream
        --after ws://127.0.0.1:8821/v1/stream [--engine NAME ...] [--streams 500]
        [--rounds 2] [--clip 10] [--note TEXT] [--results bench/first_frame_priority.json]
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ..loadtest.load import LoadTestConfig, loadtest
from ..results_file import recorded, script_command, write_results

SIDES = ("before", "after")
PAUSE_S = 5.0
WARMUP_STREAMS = 100


def run_summary(results: dict[str, Any]) -> dict[str, Any]:
    """The figures of one load test that the report shows (its one clip)."""
    [clip] = results["clips"]
    probe = clip["probe"]
    return {
        "probe_requests": probe["requests"],
        "probe_errors": probe["errors"],
        "first_frame_ms": {
            key: probe["first_frame_latency_ms"][key] for key in ("p50", "p99", "max")
        },
        "frame_lag_ms": {key: clip["frame_lag_ms"][key] for key in ("p50", "p99")},
        "peak_sessions": clip["peak_sessions"],
        "requests": clip["requests"],
        "errors": clip["errors"],
    }


def measure(
    urls: dict[str, str], engines: Sequence[str], base: LoadTestConfig, rounds: int
) -> list[dict[str, Any]]:
    """Every engine's rounds, both servers in each, alternating which goes first."""
    rows: list[dict[str, Any]] = []
    for engine in engines:
        for side in SIDES:  # a server's first load of an engine loads its kernels: not measured
            warm = {**vars(base), "streams": WARMUP_STREAMS, "requests": WARMUP_STREAMS}
            loadtest(LoadTestConfig(**{**warm, "url": urls[side], "engine": engine}))
            time.sleep(PAUSE_S)
        for number in range(rounds):
            order = SIDES if number % 2 == 0 else SIDES[::-1]
            for side in order:
                config = LoadTestConfig(**{**vars(base), "url": urls[side], "engine": engine})
                summary = run_summary(loadtest(config))
                rows.append({"engine": engine, "round": number, "side": side, **summary})
                print(engine, number, side, summary["first_frame_ms"], flush=True)
                time.sleep(PAUSE_S)
    return rows


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--before", required=True, help="ws:// URL of the server before")
    parser.add_argument("--after", required=True, help="ws:// URL of the server after")
    parser.add_argument("--engine", action="append", default=None)
    parser.add_argument("--character", default="demo")
    parser.add_argument("--streams", type=int, default=500)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--clip", type=float, default=10.0)
    parser.add_argument("--probe-phonemes", type=int, default=30)
    parser.add_argument("--latency-budget-ms", type=float, default=20.0)
    parser.add_argument("--note", default="")
    parser.add_argument("--results", type=Path, default=Path("bench/first_frame_priority.json"))
    args = parser.parse_args(argv)
    base = LoadTestConfig(
        streams=args.streams,
        requests=args.streams,
        clips_s=(args.clip,),
        character=args.character,
        latency_budget_ms=args.latency_budget_ms,
        lead_ms=0.0,
        probe_phonemes=args.probe_phonemes,
    )
    engines = args.engine or ["anime-graph", "hmm"]
    rows = measure({"before": args.before, "after": args.after}, engines, base, args.rounds)
    results = {
        **recorded(script_command("lipstream.bench.first_frame_priority", argv)),
        "note": args.note,
        "streams": args.streams,
        "clip_s": args.clip,
        "probe_phonemes": args.probe_phonemes,
        "lead_ms": 0.0,
        "latency_budget_ms": args.latency_budget_ms,
        "target_p99_ms": 50.0,
        "rows": rows,
    }
    write_results(results, args.results)
    print(f"results written to {args.results}")


if __name__ == "__main__":
    main()
