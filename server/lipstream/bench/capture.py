"""How fast ``lipstream capture`` runs on one core: frames tracked per second, and the
other steps beside it.

Method: the process pins itself to one CPU before mediapipe is imported (so FaceMesh's
inference threads share that core), then, ``--repeats`` times over the same video:
decodes every frame to RGB (``decode``), runs FaceMesh in tracking mode over the decoded
frames with a fresh FaceMesh each time, creation left out (``track``), and runs the whole
per-video step, decoding, tracking, pose removal and forced alignment
(``pipeline.track_clip``). Each figure is the median over the repeats of frames (or audio
seconds) per wall-clock second, and the same per CPU second of the process (what the
core gave it: on a shared machine wall-clock rates fall with the load, which is recorded
before and after). The alignment's real-time factor is its share of the whole step:
whole minus decode and track, in wall-clock and in CPU seconds.

    python -m lipstream.bench.capture VIDEO [--repeats 5] [--json FILE]

The video's transcript is the same-stem ``.txt`` beside it. The results go to ``--json``,
by default ``$LIPSTREAM_HOME/bench/capture.json``; ``--json bench/capture.json`` in a
checkout replaces the committed one.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from .._version import __version__
from ..config import load_settings
from ..results_file import machine, write_results

COMMAND = "python -m lipstream.bench.capture"


def pin_to_one_core() -> int:
    """Pin this process (and the threads it starts later) to its first allowed CPU."""
    core = min(os.sched_getaffinity(0))
    os.sched_setaffinity(0, {core})
    return core


def _timed(step: Callable[[], object]) -> tuple[float, float]:
    wall, cpu = time.perf_counter(), time.process_time()
    step()
    return time.perf_counter() - wall, time.process_time() - cpu


def measure(video: Path, repeats: int) -> dict[str, Any]:
    from ..capture.decode import read_frames
    from ..capture.jobs import capture_jobs
    from ..capture.pipeline import track_clip
    from ..capture.track import face_mesh

    [job] = capture_jobs([str(video)], None)
    frames = list(read_frames(video))
    audio_s = track_clip(job).audio.duration  # also a warm-up: models loaded, caches filled
    runs: dict[str, list[tuple[float, float]]] = {"decode": [], "track": [], "capture": []}
    for _ in range(repeats):
        runs["decode"].append(_timed(lambda: list(read_frames(video))))
        with face_mesh() as mesh:
            runs["track"].append(_timed(lambda: [mesh.process(f.rgb) for f in frames]))
        runs["capture"].append(_timed(lambda: track_clip(job)))
    wall = {step: statistics.median(w for w, _ in timings) for step, timings in runs.items()}
    cpu = {step: statistics.median(c for _, c in timings) for step, timings in runs.items()}
    align_s = max(wall["capture"] - wall["decode"] - wall["track"], 0.0)
    align_cpu_s = max(cpu["capture"] - cpu["decode"] - cpu["track"], 0.0)
    return {
        "video": video.name,
        "frames": len(frames),
        "audio_s": round(audio_s, 3),
        "repeats": repeats,
        "decode_fps": round(len(frames) / wall["decode"], 1),
        "tracking_fps": round(len(frames) / wall["track"], 1),
        "capture_fps": round(len(frames) / wall["capture"], 1),
        "alignment_real_time_factor": round(align_s / audio_s, 3),
        "per_cpu_second": {
            "decode_fps": round(len(frames) / cpu["decode"], 1),
            "tracking_fps": round(len(frames) / cpu["track"], 1),
            "capture_fps": round(len(frames) / cpu["capture"], 1),
            "alignment_real_time_factor": round(align_cpu_s / audio_s, 3),
        },
        "wall_s": {step: round(seconds, 3) for step, seconds in wall.items()},
        "cpu_s": {step: round(seconds, 3) for step, seconds in cpu.items()},
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog=COMMAND, description=__doc__.splitlines()[0])
    parser.add_argument("video", help="a video with its same-stem .txt transcript beside it")
    parser.add_argument("--repeats", type=int, default=5, help="runs per step (default 5)")
    parser.add_argument("--json", help="results file (default $LIPSTREAM_HOME/bench/capture.json)")
    args = parser.parse_args(argv)
    host = machine()
    core = pin_to_one_core()
    before = os.getloadavg()[0]
    run = measure(Path(args.video), args.repeats)
    results = {
        "command": f"{COMMAND} {args.video} --repeats {args.repeats}",
        "lipstream_version": __version__,
        "date": datetime.now(UTC).isoformat(timespec="seconds"),
        "machine": host | {"pinned_to_core": core},
        "load_average_1min": {"before": before, "after": os.getloadavg()[0]},
        "runs": [run],
    }
    path = load_settings().results_file(args.json, "capture.json")
    write_results(results, path)
    print(
        f"{run['tracking_fps']} frames tracked per second on one core "
        f"({run['per_cpu_second']['tracking_fps']} per CPU second); whole capture "
        f"{run['capture_fps']} frames per second; wrote {path}"
    )


if __name__ == "__main__":
    main()
