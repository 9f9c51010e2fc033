"""Where a serving process's CPU goes: py-spy's sampled stacks sorted into the server's layers.

Sketch: ``py-spy record --format raw`` writes one line per distinct stack,
its frames from the outermost to the innermost separated by ``;`` and the
sample count after the last space, each frame ``function (file:line)``. A
sample belongs to the first layer in ``LAYERS`` that any of its frames
matches, so a layer nested inside another (the engine call inside the
session, a metric recorded on the send path) is counted as itself, not as
its caller. Samples that match none are the event loop's own work and the
rest of the web stack (``other``). Stacks without the event loop's
``run_forever`` are other threads' (the synthesis pool, among them workers
py-spy did not see as idle): ``other threads``. The result also lists the innermost
functions that took the most samples.

Usage::

    py-spy record --pid PID --duration 20 --rate 200 --format raw --output stacks.txt
    python -m lipstream.bench.server_profile stacks.txt --command "..." \\
        --results bench/server_profile.json
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
from collections import Counter
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from ..results_file import write_results

LAYERS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("engine call", ("lipstream/engines/", "lipstream/numerics/")),
    ("metrics", ("prometheus_client/",)),
    ("session and request layers", ("lipstream/server/session.py", "lipstream/server/request.py")),
    ("send path", ("_send_all (", "_send_payload (", "_send (", "asgi_send (", "send (starlette")),
    (
        "receiving and decoding",
        (
            "_receive (",
            "_decode (",
            "asgi_receive (",
            "lipstream_client/codec",
            "data_received (",
            "read_window",
        ),
    ),
    ("event loop polling", ("select (selectors.py", "poll (selectors.py")),
)
OTHER = "other"
OTHER_THREADS = "other threads"
EVENT_LOOP = "run_forever ("
TOP_FUNCTIONS = 15


def parse_line(line: str) -> tuple[list[str], int] | None:
    """(frames outermost first, samples) of one raw line; None for a line that is not one."""
    stack, _, count = line.rstrip("\n").rpartition(" ")
    if not stack or not count.isdigit():
        return None
    return stack.split(";"), int(count)


def layer_of(frames: Sequence[str]) -> str:
    """``OTHER_THREADS`` for a stack outside the event loop's thread, else the first layer
    of ``LAYERS`` any frame matches, else ``OTHER``."""
    if not any(EVENT_LOOP in frame for frame in frames):
        return OTHER_THREADS
    for name, patterns in LAYERS:
        if any(pattern in frame for frame in frames for pattern in patterns):
            return name
    return OTHER


def breakdown(lines: Iterable[str]) -> dict[str, Any]:
    """Samples in all, per layer (in ``LAYERS`` order, then ``OTHER`` and
    ``OTHER_THREADS``) and per innermost function of the event loop's thread."""
    layers: Counter[str] = Counter()
    leaves: Counter[str] = Counter()
    for line in lines:
        parsed = parse_line(line)
        if parsed is None:
            continue
        frames, samples = parsed
        layer = layer_of(frames)
        layers[layer] += samples
        if layer != OTHER_THREADS:
            leaves[frames[-1]] += samples
    total = sum(layers.values())
    loop_total = total - layers[OTHER_THREADS]
    names = [name for name, _ in LAYERS] + [OTHER, OTHER_THREADS]
    return {
        "samples": total,
        "event_loop_samples": loop_total,
        "layers": [
            {
                "layer": name,
                "samples": layers[name],
                "share": layers[name] / total if total else 0.0,
                "share_of_event_loop": None
                if name == OTHER_THREADS or not loop_total
                else layers[name] / loop_total,
            }
            for name in names
        ],
        "top_functions": [
            {"function": name, "samples": count, "share_of_event_loop": count / loop_total}
            for name, count in leaves.most_common(TOP_FUNCTIONS)
        ],
    }


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("stacks", type=Path, help="py-spy record --format raw output")
    parser.add_argument("--command", required=True, help="how the load and the profile ran")
    parser.add_argument("--results", type=Path, default=Path("bench/server_profile.json"))
    args = parser.parse_args(argv)
    with args.stacks.open(encoding="utf-8") as stacks:
        result = breakdown(stacks)
    write_results(
        {
            "tool": "py-spy record --format raw, sorted by lipstream.bench.server_profile",
            "machine": {
                "cpus": os.cpu_count(),
                "platform": platform.platform(),
                "python": platform.python_version(),
            },
            "date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC"),
            "command": args.command,
            **result,
        },
        args.results,
    )
    print(f"{result['samples']} samples sorted into {args.results}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
