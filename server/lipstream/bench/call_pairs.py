"""Per-call CPU of two source trees side by side: does a change make a streamed call dearer?

Method: ``pairs`` rounds; in each, ``floor_calls`` measures the same engines and rungs once
with each tree's code (a subprocess whose ``PYTHONPATH`` puts that tree's ``server`` and
``client_sdk`` first), the tree that goes first alternating from round to round, so that
drifts of the machine's speed fall on both alike. Each run reports the thread CPU per
feed+frames call (median and mean over its requests). Reported per engine and rung: each
tree's median, over the rounds, of the runs' medians and means, the ratio after / before of
those, and in how many rounds the after tree's median was the lower. A machine shared with
other work widens the spread of single runs; the ratio of medians over alternating rounds
is what stays comparable.

    python -m lipstream.bench.call_pairs --before TREE --after TREE --models DIR
        [--engine NAME ...] [--all-rungs] [--pairs 5] [--calls 200] [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ..results_file import recorded, script_command, write_results
from .report import rows_of


def tree_revision(tree: Path) -> str:
    """``git describe --always --dirty`` of ``tree``, or its path when it is not a checkout."""
    result = subprocess.run(
        ["git", "-C", str(tree), "describe", "--always", "--dirty"],
        capture_output=True,
        text=True,
        check=False,
    )
    return result.stdout.strip() if result.returncode == 0 else str(tree)


def measure_tree(tree: Path, floor_args: Sequence[str]) -> list[dict[str, Any]]:
    """One ``floor_calls`` run with ``tree``'s code; its rows."""
    with tempfile.TemporaryDirectory() as scratch:
        out = Path(scratch) / "rows.json"
        path = os.pathsep.join([str(tree / "server"), str(tree / "client_sdk")])
        environment = {**os.environ, "PYTHONPATH": path}
        command = [sys.executable, "-m", "lipstream.bench.floor_calls", *floor_args]
        subprocess.run(
            [*command, "--json", str(out)], env=environment, check=True, capture_output=True
        )
        return rows_of(json.loads(out.read_text()))


def compare(
    before: list[list[dict[str, Any]]], after: list[list[dict[str, Any]]]
) -> list[dict[str, Any]]:
    """Per (engine, rung): both trees' medians over the rounds and the after/before ratios."""
    keys = [(row["engine"], row["rung"]) for row in before[0]]
    rows = []
    for key in keys:
        old = [_row(run, key) for run in before]
        new = [_row(run, key) for run in after]
        old_median = statistics.median(row["median_us"] for row in old)
        new_median = statistics.median(row["median_us"] for row in new)
        old_mean = statistics.median(row["mean_us"] for row in old)
        new_mean = statistics.median(row["mean_us"] for row in new)
        rows.append(
            {
                "engine": key[0],
                "rung": key[1],
                "before_median_us": old_median,
                "after_median_us": new_median,
                "median_ratio": round(new_median / old_median, 3),
                "before_mean_us": old_mean,
                "after_mean_us": new_mean,
                "mean_ratio": round(new_mean / old_mean, 3),
                "rounds_after_lower": sum(
                    b["median_us"] < a["median_us"] for a, b in zip(old, new)
                ),
                "rounds": len(old),
            }
        )
    return rows


def _row(run: list[dict[str, Any]], key: tuple[str, str]) -> dict[str, Any]:
    return next(row for row in run if (row["engine"], row["rung"]) == key)


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", type=Path, required=True, help="the tree before the change")
    parser.add_argument("--after", type=Path, required=True, help="the tree after the change")
    parser.add_argument("--models", type=Path, required=True, help="model directory")
    parser.add_argument("--engine", action="append", help="engine (repeatable; default all)")
    parser.add_argument("--all-rungs", action="store_true", help="every rung, not only causal")
    parser.add_argument("--pairs", type=int, default=5, help="alternating rounds")
    parser.add_argument("--calls", type=int, default=200, help="calls per request")
    parser.add_argument("--json", type=Path, help="write the results here")
    args = parser.parse_args(argv)
    floor_args = ["--models", str(args.models), "--calls", str(args.calls)]
    for engine in args.engine or []:
        floor_args += ["--engine", engine]
    if args.all_rungs:
        floor_args.append("--all-rungs")
    runs: dict[str, list[list[dict[str, Any]]]] = {"before": [], "after": []}
    for round_ in range(args.pairs):
        order = ("before", "after") if round_ % 2 == 0 else ("after", "before")
        for side in order:
            runs[side].append(measure_tree(getattr(args, side), floor_args))
    rows = compare(runs["before"], runs["after"])
    for row in rows:
        print(
            f"{row['engine']:15s} {row['rung']:18s} median {row['before_median_us']:8.1f} → "
            f"{row['after_median_us']:8.1f} µs ({row['median_ratio']:.3f}×)   mean "
            f"{row['before_mean_us']:8.1f} → {row['after_mean_us']:8.1f} µs "
            f"({row['mean_ratio']:.3f}×)"
        )
    if args.json is not None:
        results = {
            **recorded(script_command("lipstream.bench.call_pairs", argv)),
            "before": tree_revision(args.before),
            "after": tree_revision(args.after),
            "rows": rows,
        }
        write_results(results, args.json)


if __name__ == "__main__":
    main()
