"""Memory of ``lipstream serve --workers N``: RSS and PSS of each process, from smaps_rollup.

Method: for each N, start ``lipstream serve --workers N`` on a free loopback
port with the given models, wait until every worker has logged its start-up
(models loaded, warmed up and calibrated) and ``/readyz`` answers, then read
``/proc/<pid>/smaps_rollup`` of the serving processes: with one worker the
process itself, with several each worker (the supervisor's children), the
supervisor, and multiprocessing's resource tracker (a helper). RSS counts
every resident page a process maps; PSS divides each shared page among the
processes that map it, so the PSS of all processes sums to what they cost
together, and RSS minus PSS is what sharing saved.
Then SIGTERM, and the next N. Linux only.

    python -m lipstream.bench.workers_memory --models DIR --workers 1 2 4 --json out.json
"""

from __future__ import annotations

import argparse
import json
from dataclasses import asdict, dataclass
from pathlib import Path

from .serving import children, serving


@dataclass(frozen=True)
class ProcessMemory:
    """One process's resident (RSS) and proportional (PSS) set sizes, in MiB."""

    pid: int
    role: str
    rss_mib: float
    pss_mib: float


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
    return ProcessMemory(pid, role, fields["Rss"] / 1024.0, fields["Pss"] / 1024.0)


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


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--models", type=Path, required=True)
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2, 4])
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)
    results: dict[str, list[dict[str, object]]] = {}
    for workers in args.workers:
        processes = measure(args.models, workers)
        results[str(workers)] = [asdict(process) for process in processes]
        workers_only = [p for p in processes if p.role == "worker"]
        total_pss = sum(p.pss_mib for p in processes)
        print(
            f"{workers} worker(s): RSS per worker "
            f"{', '.join(f'{p.rss_mib:.0f}' for p in workers_only)} MiB; PSS per worker "
            f"{', '.join(f'{p.pss_mib:.0f}' for p in workers_only)} MiB; "
            f"PSS of all processes {total_pss:.0f} MiB"
        )
    if args.json is not None:
        args.json.write_text(json.dumps(results, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
