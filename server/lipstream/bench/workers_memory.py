"""Memory of ``lipstream serve --workers N``: RSS, PSS and USS of each process (smaps_rollup).

Method: first one unmeasured start with one worker, so that numba's kernel
cache is warm: the figures are those of every later start (a first start
also keeps the memory that compiling the kernels took).
Then, for each N, start ``lipstream serve --workers N`` on a free loopback
port with the given models, wait until every worker has logged its start-up
(models loaded, warmed up and calibrated) and ``/readyz`` answers, then read
``/proc/<pid>/smaps_rollup`` of the serving processes: with one worker the
process itself, with several each worker (the supervisor's children), the
supervisor, and multiprocessing's resource tracker (a helper). RSS counts
every resident page a process maps; PSS divides each shared page among the
processes that map it, so the PSS of all processes sums to what they cost
together, and RSS minus PSS is what sharing saved; USS counts the pages
the process alone maps (private), which no sharing can save. PSS also
shares library pages with unrelated processes mapping the same files (other
Python programs' numpy), so on a busy machine it is lower; USS is not.
Then SIGTERM, and the next N. Linux only. ``--markdown`` prints the deploy
guide's table (docs/how-to/deploy.md) rendered from a results file.

    python -m lipstream.bench.workers_memory --models DIR --workers 1 2 4 --json out.json
    python -m lipstream.bench.workers_memory --markdown bench/workers_memory.json
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shlex
import sys
from dataclasses import asdict, dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from .._version import __version__
from ..models import model_dirs
from ..store import read_manifest
from .serving import children, serving

TOOL = "python -m lipstream.bench.workers_memory"


@dataclass(frozen=True)
class ProcessMemory:
    """One process's resident (RSS), proportional (PSS) and unique (USS) set sizes, in MiB."""

    pid: int
    role: str
    rss_mib: float
    pss_mib: float
    uss_mib: float


def smaps_rollup(pid: int) -> dict[str, int]:
    """The kB fields of ``/proc/<pid>/smaps_rollup``."""
    fields: dict[str, int] = {}
    for line in Path(f"/proc/{pid}/smaps_rollup").read_text().splitlines()[1:]:
        name, _, rest = line.partition(":")
        parts = rest.split()
        if parts and parts[0].isdigit():
            fields[name.strip()] = int(parts[0])
    return fields


def memory_of(pid: int, role: str) -> ProcessMemory:
    fields = smaps_rollup(pid)
    private = fields["Private_Clean"] + fields["Private_Dirty"]
    return ProcessMemory(
        pid, role, fields["Rss"] / 1024.0, fields["Pss"] / 1024.0, private / 1024.0
    )


def role_of(pid: int) -> str:
    """``worker`` for a uvicorn worker, ``helper`` for multiprocessing's resource tracker."""
    command = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ")
    return "helper" if b"resource_tracker" in command else "worker"


def measure(models: Path, workers: int) -> list[ProcessMemory]:
    """Start the server with ``workers`` workers, measure every serving process, stop it."""
    with serving(models, workers) as served:
        pid = served.process.pid
        if workers == 1:
            return [memory_of(pid, "worker")]
        return [memory_of(pid, "supervisor")] + [
            memory_of(child, role_of(child)) for child in children(pid)
        ]


def describe_models(models: Path) -> list[dict[str, Any]]:
    """Each model directory served: its name, engine and size on disk in bytes."""
    described = []
    for directory in model_dirs(models):
        files = [path for path in directory.rglob("*") if path.is_file()]
        described.append(
            {
                "name": directory.name,
                "engine": read_manifest(directory).engine,
                "bytes": sum(path.stat().st_size for path in files),
            }
        )
    return described


def machine() -> dict[str, Any]:
    return {
        "cpus": os.cpu_count(),
        "platform": platform.platform(),
        "python": platform.python_version(),
        "load_average": [round(load, 2) for load in os.getloadavg()],
    }


def run(models: Path, workers: list[int], argv: list[str]) -> dict[str, Any]:
    """The results file: how it was measured, then every process of each ``--workers N``."""
    results: dict[str, Any] = {
        "tool": f"lipstream.bench.workers_memory {__version__}",
        "command": shlex.join([*TOOL.split(), *argv]),
        "date": datetime.now(UTC).isoformat(timespec="seconds"),
        "machine": machine(),
        "models": describe_models(models),
        "workers": {},
    }
    with serving(models, 1):
        pass
    for count in workers:
        processes = measure(models, count)
        results["workers"][str(count)] = [asdict(process) for process in processes]
        print(summary_line(count, processes), flush=True)
    return results


def summary_line(workers: int, processes: list[ProcessMemory]) -> str:
    workers_only = [p for p in processes if p.role == "worker"]
    return (
        f"{workers} worker(s): RSS per worker "
        f"{', '.join(f'{p.rss_mib:.0f}' for p in workers_only)} MiB; PSS per worker "
        f"{', '.join(f'{p.pss_mib:.0f}' for p in workers_only)} MiB; USS per worker "
        f"{', '.join(f'{p.uss_mib:.0f}' for p in workers_only)} MiB; "
        f"PSS of all processes {sum(p.pss_mib for p in processes):.0f} MiB"
    )


HEADER = (
    "| workers | RSS per worker | PSS per worker | USS per worker | supervisor (RSS / PSS) "
    "| all processes, PSS |\n|---|---|---|---|---|---|"
)


def _mean(values: list[float]) -> float:
    return sum(values) / len(values)


def _of_role(processes: list[dict[str, Any]], role: str) -> list[dict[str, Any]]:
    return [process for process in processes if process["role"] == role]


def _row(workers: str, processes: list[dict[str, Any]]) -> str:
    """One table row; a worker's figures are the mean over the workers."""
    each = _of_role(processes, "worker")
    rss = _mean([p["rss_mib"] for p in each])
    pss = _mean([p["pss_mib"] for p in each])
    uss = _mean([p["uss_mib"] for p in each])
    held = "(none: the process is the worker)"
    for supervisor in _of_role(processes, "supervisor"):
        held = f"{supervisor['rss_mib']:.0f} / {supervisor['pss_mib']:.0f} MiB"
    total = sum(p["pss_mib"] for p in processes)
    own = f"{rss:.0f} MiB | {pss:.0f} MiB | {uss:.0f} MiB"
    return f"| {workers} | {own} | {held} | {total:.0f} MiB |"


def _sharing(by_count: dict[int, list[dict[str, Any]]]) -> list[str]:
    """The resource tracker's cost, what a worker shares (its RSS less its PSS) and the
    cost per worker: the line through the two largest N's totals."""
    several = {count: processes for count, processes in by_count.items() if count > 1}
    helpers = [p for processes in several.values() for p in _of_role(processes, "helper")]
    lines = []
    if helpers:
        lines.append(
            f"With several workers, multiprocessing's resource tracker adds "
            f"{_mean([p['rss_mib'] for p in helpers]):.0f} MiB RSS, "
            f"{_mean([p['pss_mib'] for p in helpers]):.0f} MiB PSS, counted in the last column."
        )
    if len(several) >= 2:
        shared = [
            _mean([p["rss_mib"] - p["pss_mib"] for p in _of_role(processes, "worker")])
            for processes in several.values()
        ]
        totals = {n: sum(p["pss_mib"] for p in processes) for n, processes in by_count.items()}
        low, high = sorted(several)[-2:]
        per_worker = (totals[high] - totals[low]) / (high - low)
        fixed = totals[high] - per_worker * high
        alone = f", against {totals[1]:.0f} MiB for one process" if 1 in totals else ""
        lines.append(
            f"A worker's RSS less its PSS, {min(shared):.0f}–{max(shared):.0f} MiB, is what it "
            "shares with the other processes that map the same pages (the other workers, "
            "the supervisor, other Python programs' libraries). "
            f"N workers cost about {fixed:.0f} MiB + "
            f"{per_worker:.0f} MiB × N (the line through N = {low} and N = {high}){alone}."
        )
    return lines


def render_markdown(results: dict[str, Any]) -> str:
    """The deploy guide's paragraph on memory: the engines, the command, the table of
    every N and what the workers share, all from ``results``."""
    engines = ", ".join(f"`{model['engine']}`" for model in results["models"])
    megabytes = sum(model["bytes"] for model in results["models"]) / 1e6
    by_count = {int(key): processes for key, processes in results["workers"].items()}
    rows = [_row(str(count), by_count[count]) for count in sorted(by_count)]
    sharing = _sharing(by_count)
    return (
        "\n".join(
            [
                f"Memory with every engine of the demo character loaded ({engines}; "
                f"{megabytes:.0f} MB of model files), measured with `{results['command']}` "
                f"on {results['date'][:10]} (`/proc/<pid>/smaps_rollup` once every worker is "
                "ready; `bench/workers_memory.json`, rendered by "
                "`python -m lipstream.bench.workers_memory --markdown bench/workers_memory.json`):",
                "",
                HEADER,
                *rows,
                *([""] + sharing if sharing else []),
            ]
        )
        + "\n"
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("--models", type=Path)
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2, 4])
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--markdown", type=Path, default=None, metavar="RESULTS")
    args = parser.parse_args(argv)
    if args.markdown is not None:
        print(render_markdown(json.loads(args.markdown.read_text())), end="")
        return 0
    if args.models is None:
        parser.error("--models is required unless --markdown is given")
    given = argv if argv is not None else sys.argv[1:]
    results = run(args.models, args.workers, list(given))
    if args.json is not None:
        args.json.write_text(json.dumps(results, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
