"""How long ``lipstream serve`` takes to become ready from an empty ``$LIPSTREAM_HOME``, and
again from the home it left (a later start), and how long it ever stays silent.

Method: each run launches ``python -m lipstream.cli serve`` on loopback with
``LIPSTREAM_HOME`` set to one fresh directory (and ``NUMBA_CACHE_DIR`` inside it,
so the first start compiles every kernel, as on a new machine). A thread stamps
every piece of its output (lines, and progress-bar redraws ending in ``\\r``) with
the time since launch; uvicorn's access-log lines for the probes below are left out,
since they are the bench's own traffic, not the server speaking. The main loop
probes ``GET /healthz`` and ``GET /readyz`` every ``PROBE_S`` until ``/readyz``
answers 200, noting when ``/healthz`` first answered 200 and when each ``/readyz``
phase was first seen. Then the server gets SIGINT, and the CPU time of its process
tree (its training workers included) is read from ``RUSAGE_CHILDREN``. The steps
come from the status lines (``what: done in N s``). The machine is shared in
general, so each run records the load average before and after it.

    python -m lipstream.bench.first_start [--json FILE] [--port 8765]

The results go to ``--json``, by default ``$LIPSTREAM_HOME/bench/first_start.json``
(never into the current directory unasked: a checkout's ``bench/`` holds the committed
measurements); ``--json bench/first_start.json`` in a checkout replaces the committed one.
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, BinaryIO

import httpx

from ..config import load_settings
from ..results_file import recorded, write_results

COMMAND = "python -m lipstream.bench.first_start"
PROBE_S = 0.2
PROBE_TIMEOUT_S = 1.0
READY_TIMEOUT_S = 1800.0
EXIT_TIMEOUT_S = 60.0
TARGETS = {"first_start_s": 60.0, "later_start_s": 5.0, "longest_silence_s": 2.0}
_DONE = re.compile(
    r"(?:INFO:\s+)?(?P<step>.+?): done in (?P<seconds>[0-9.]+) s(?: \((?P<detail>.*)\))?"
)
_PROBE_LOG = re.compile(r'"GET /(?:healthz|readyz) HTTP/1\.[01]" \d{3}')


@dataclass
class Step:
    step: str
    seconds: float
    ended_s: float
    detail: str = ""


@dataclass
class Run:
    """One start, from launch (times in s since then)."""

    first_output_s: float | None = None
    first_health_s: float | None = None
    ready_s: float | None = None
    longest_silence_s: float | None = None
    cpu_s: float | None = None
    load_average_before: tuple[float, float, float] = (0.0, 0.0, 0.0)
    load_average_after: tuple[float, float, float] = (0.0, 0.0, 0.0)
    phases_seen_s: dict[str, float] = field(default_factory=dict)
    steps: list[Step] = field(default_factory=list)


def steps_from(output: list[tuple[float, str]]) -> list[Step]:
    """The ``what: done in N s`` status lines of ``output`` ((time, text) pairs)."""
    found = []
    for at, text in output:
        match = _DONE.fullmatch(text.strip())
        if match:
            detail = match["detail"] or ""
            found.append(Step(match["step"], float(match["seconds"]), round(at, 2), detail))
    return found


def longest_silence(output: list[tuple[float, str]], until: float) -> float | None:
    """The longest time between consecutive pieces of ``output`` (probe log lines aside),
    up to ``until``; ``None`` with no output."""
    times = [at for at, text in output if at <= until and not _PROBE_LOG.search(text)]
    if not times:
        return None
    times.append(until)
    return max(later - earlier for earlier, later in zip(times, times[1:], strict=False))


def _read_output(stream: BinaryIO, began: float, into: list[tuple[float, str]]) -> None:
    pending = b""
    while chunk := stream.read1(65536):  # type: ignore[attr-defined]
        now = time.monotonic() - began
        pending += chunk
        *pieces, pending = re.split(rb"[\r\n]", pending)
        into.extend((now, piece.decode("utf-8", "replace")) for piece in pieces if piece.strip())
    if pending.strip():
        into.append((time.monotonic() - began, pending.decode("utf-8", "replace")))


def start_once(home: Path, port: int, log: Path) -> Run:
    """Launch ``lipstream serve`` with ``home`` until ready, then stop it."""
    environment = dict(os.environ, LIPSTREAM_HOME=str(home), NUMBA_CACHE_DIR=str(home / "numba"))
    environment.pop("LIPSTREAM_MODELS", None)  # serve the demo character, built in ``home``
    command = [sys.executable, "-m", "lipstream.cli", "serve", "--host", "127.0.0.1"]
    command += ["--port", str(port)]
    run = Run(load_average_before=os.getloadavg())
    cpu_before = _children_cpu_s()
    output: list[tuple[float, str]] = []
    began = time.monotonic()
    process = subprocess.Popen(
        command, env=environment, stdout=subprocess.PIPE, stderr=subprocess.STDOUT
    )
    assert process.stdout is not None
    reader = threading.Thread(target=_read_output, args=(process.stdout, began, output))
    reader.start()
    base = f"http://127.0.0.1:{port}"
    try:
        with httpx.Client(timeout=PROBE_TIMEOUT_S) as client:
            while run.ready_s is None:
                now = time.monotonic() - began
                if now > READY_TIMEOUT_S or process.poll() is not None:
                    raise RuntimeError(f"the server never turned ready; see {log}")
                _probe(client, base, lambda: time.monotonic() - began, run)
                time.sleep(PROBE_S)
    finally:
        process.send_signal(signal.SIGINT)
        try:
            process.wait(EXIT_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
        reader.join()
        log.write_text("".join(f"{at:8.2f} {text}\n" for at, text in output), encoding="utf-8")
    run.cpu_s = round(_children_cpu_s() - cpu_before, 1)
    run.load_average_after = os.getloadavg()
    spoken = [(at, text) for at, text in output if not _PROBE_LOG.search(text)]
    run.first_output_s = round(spoken[0][0], 2) if spoken else None
    silence = longest_silence(output, run.ready_s or 0.0)
    run.longest_silence_s = None if silence is None else round(silence, 2)
    run.steps = [
        replace(step, step=step.step.replace(str(home), "$LIPSTREAM_HOME"))
        for step in steps_from(output)
    ]
    return run


def _probe(client: httpx.Client, base: str, since: Callable[[], float], run: Run) -> None:
    """One probe of each route; a time noted is when its answer arrived."""
    try:
        if run.first_health_s is None and client.get(f"{base}/healthz").status_code == 200:
            run.first_health_s = round(since(), 2)
        ready = client.get(f"{base}/readyz")
    except httpx.HTTPError:
        return  # not listening yet
    answered = round(since(), 2)
    run.phases_seen_s.setdefault(str(ready.json().get("phase", "?")), answered)
    if ready.status_code == 200:
        run.ready_s = answered


def _children_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def bench(home: Path, port: int) -> dict[str, Any]:
    """A first start from the empty ``home``, then a later one from what it left, in the
    shape ``lipstream.bench.report`` renders (``starts``: start, total_s, phases)."""
    runs = {"first": start_once(home, port, home / "first-start.log")}
    runs["later"] = start_once(home, port, home / "later-start.log")
    load = ", ".join(
        f"{name} start {run.load_average_before[0]:.1f} before, "
        f"{run.load_average_after[0]:.1f} after"
        for name, run in runs.items()
    )
    cpu = ", ".join(f"{name} start {run.cpu_s} s" for name, run in runs.items())
    return {
        **recorded(COMMAND),
        "note": (
            f"load average (1 min): {load}; CPU time of the server's process tree: {cpu}; "
            f"targets: {TARGETS}"
        ),
        "targets": TARGETS,
        "starts": [_start(name, run) for name, run in runs.items()],
    }


def _start(name: str, run: Run) -> dict[str, Any]:
    phases = {step.step: step.seconds for step in run.steps}
    return {"start": name, "total_s": run.ready_s, "phases": phases, **asdict(run)}


def _summary(results: dict[str, Any]) -> str:
    return "\n".join(
        f"{run['start']} start: ready in {run['ready_s']} s ({run['cpu_s']} s of CPU), "
        f"/healthz from {run['first_health_s']} s, first line at {run['first_output_s']} s, "
        f"longest silence {run['longest_silence_s']} s, "
        f"load average {run['load_average_before'][0]:.1f}"
        for run in results["starts"]
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--json", help="where to write (default $LIPSTREAM_HOME/bench/first_start.json)"
    )
    parser.add_argument("--port", type=int, default=8765, help="loopback port to serve on")
    parser.add_argument(
        "--home", help="an empty directory for $LIPSTREAM_HOME (default: a fresh temporary one)"
    )
    args = parser.parse_args(argv)
    home = Path(args.home) if args.home else Path(tempfile.mkdtemp(prefix="lipstream-first-"))
    if home.exists() and any(home.iterdir()):
        print(f"error [invalid_setting]: --home: {home} is not empty", file=sys.stderr)
        return 2
    home.mkdir(parents=True, exist_ok=True)
    results = bench(home, args.port)
    out = load_settings().results_file(args.json, "first_start.json")
    write_results(results, out)
    print(_summary(results))
    print(f"wrote {out}; each server's output, time-stamped, is in {home}/*.log", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
