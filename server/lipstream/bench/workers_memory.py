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
Then SIGTERM, and the next N. Linux only. ``lipstream.bench.report`` renders
the results into docs/reports/scale-out.md.

    python -m lipstream.bench.workers_memory --models DIR --workers 1 2 4 --json out.json
"""

from __future__ import annotations

import argparse
import os
import shlex
import sys
from dataclasses import asdict, dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from .._version import __version__
from ..models import model_dirs
from ..results_file import machine, write_results
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


def run(models: Path, workers: list[int], argv: list[str]) -> dict[str, Any]:
    """The results file: how it was measured, then every process of each ``--workers N``."""
    results: dict[str, Any] = {
        "tool": f"lipstream.bench.workers_memory {__version__}",
        "command": shlex.join([*TOOL.split(), *argv]),
        "date": datetime.now(UTC).isoformat(timespec="seconds"),
        "machine": {**machine(), "load_average": [round(load, 2) for load in os.getloadavg()]},
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


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("--models", type=Path, required=True)
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2, 4])
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)
    given = argv if argv is not None else sys.argv[1:]
    results = run(args.models, args.workers, list(given))
    if args.json is not None:
        write_results(results, args.json)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
