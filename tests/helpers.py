"""Test helpers shared across test modules (imported as ``helpers``)."""

from __future__ import annotations

import asyncio
import json
import os
import selectors
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Coroutine
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

if TYPE_CHECKING:
    import numpy as np

    from lipstream.engines.base import Model
    from lipstream.timeline import PhonemeSpan

REPO = Path(__file__).resolve().parents[1]
# Real Live Link Face exports, when present: .ci/run points it at ../shared/data/livelink-face.
LIVELINK_DIR_VARIABLE = "LIPSTREAM_LIVELINK_DIR"
# A wait is a number of polls, not a speed: a minute of pauses, generous on a loaded machine.
EVENTUALLY_POLLS = 3000
EVENTUALLY_PAUSE_S = 0.02
T = TypeVar("T")
# VRM 1.0's preset expressions that the `vrm1` rig preset drives, in its order (VRMC_vrm
# expressions.md); written out here, not read from lipstream.output, so tests check it.
VRM1_EXPRESSIONS = (
    "aa",
    "ih",
    "ou",
    "ee",
    "oh",
    "blink",
    "happy",
    "angry",
    "sad",
    "relaxed",
    "surprised",
    "neutral",
)


def eventually(
    condition: Callable[[], T],
    what: str,
    polls: int = EVENTUALLY_POLLS,
    pause_s: float = EVENTUALLY_PAUSE_S,
) -> T:
    """The first truthy value of ``condition()``, asked up to ``polls`` times ``pause_s``
    apart. It fails the test only when the condition never held, however long each poll
    took: a bound on waiting, not on speed."""
    for _ in range(polls):
        value = condition()
        if value:
            return value
        time.sleep(pause_s)
    raise AssertionError(f"never held in {polls} polls {pause_s:g} s apart: {what}")


def real_livelink_takes() -> list[Path]:
    """The ``*.csv`` exports in ``$LIPSTREAM_LIVELINK_DIR``; none when the variable is unset."""
    directory = os.environ.get(LIVELINK_DIR_VARIABLE, "").strip()
    return sorted(Path(directory).glob("*.csv")) if directory else []


class VirtualClock:
    """Loop time for ``run_on_virtual_time``: it stands still while callbacks run, and a test
    may move it on by hand (``now``) to stand for a loop held up."""

    def __init__(self) -> None:
        self.now = 0.0

    def time(self) -> float:
        return self.now


class _JumpingSelector(selectors.DefaultSelector):
    """Where the loop would sleep until its next timer, the clock jumps there instead."""

    def __init__(self, clock: VirtualClock) -> None:
        super().__init__()
        self.clock = clock

    def select(self, timeout: float | None = None) -> list[tuple[Any, int]]:
        ready: list[tuple[Any, int]] = super().select(0)
        if ready or timeout == 0:
            return ready
        if timeout is None:  # no timer at all: only real I/O can wake the loop
            waited: list[tuple[Any, int]] = super().select(None)
            return waited
        self.clock.now += timeout
        return ready


def run_on_virtual_time(
    scenario: Callable[[VirtualClock], Coroutine[Any, Any, T]],
) -> T:
    """Run ``scenario(clock)`` on an event loop whose ``time()`` is ``clock``: timers fire
    in their order at exactly their due times, however slow the machine, and no test waits
    for them in wall time."""
    clock = VirtualClock()
    loop = asyncio.SelectorEventLoop(_JumpingSelector(clock))
    loop.time = clock.time  # type: ignore[method-assign]  # the loop reads the fake clock
    try:
        return loop.run_until_complete(scenario(clock))
    finally:
        loop.close()


def run_cli(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    """Run the real ``lipstream`` entry point in a subprocess."""
    return subprocess.run(
        [sys.executable, "-m", "lipstream.cli", *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=300,
    )


def serve_command(models: Path, port: int, *flags: str) -> list[str]:
    """The real ``lipstream serve`` of ``models`` on loopback ``port``, as a subprocess argv."""
    return [
        sys.executable,
        "-m",
        "lipstream.cli",
        "serve",
        "--models",
        str(models),
        "--host",
        "127.0.0.1",
        "--port",
        str(port),
        *flags,
    ]


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port: int = probe.getsockname()[1]
        return port


def textgrid_long(intervals: list[tuple[float, float, str]], tier: str = "phones") -> str:
    """A long-format Praat TextGrid with one interval tier, as Praat and MFA write it."""
    xmax = intervals[-1][1]
    lines = [
        'File type = "ooTextFile"',
        'Object class = "TextGrid"',
        "",
        "xmin = 0",
        f"xmax = {xmax}",
        "tiers? <exists>",
        "size = 1",
        "item []:",
        "    item [1]:",
        '        class = "IntervalTier"',
        f'        name = "{tier}"',
        "        xmin = 0",
        f"        xmax = {xmax}",
        f"        intervals: size = {len(intervals)}",
    ]
    for number, (start, end, label) in enumerate(intervals, 1):
        lines += [
            f"        intervals [{number}]:",
            f"            xmin = {start}",
            f"            xmax = {end}",
            f'            text = "{label}"',
        ]
    return "\n".join(lines) + "\n"


def rest_pose(model: Model, emotion: str | None) -> np.ndarray:
    """The character's rest pose as its model holds it: the model's face in the middle of
    one second of silence, float32 (n_channels,)."""
    import numpy as np

    from lipstream.phonemes import SILENCE
    from lipstream.timeline import PhonemeSpan

    silence = [PhonemeSpan(SILENCE, 0.0, 1.0)]
    frames = model.synthesize(silence, fps=float(model.manifest.fps), emotion=emotion).frames
    return np.asarray(frames[len(frames) // 2], dtype=np.float32)


def return_frames(fps: float, return_ms: float = 150.0) -> int:
    """The frames a request sends after its input's end to return the face to rest: its
    return time (the server's default, 150 ms) at ``fps``, rounded up, at least one."""
    import math

    return max(1, math.ceil(round(return_ms * fps / 1000.0, 9)))


def delayed_spans(spans: list[PhonemeSpan], delay: float) -> list[PhonemeSpan]:
    """``spans`` with every boundary ``delay`` s later, the first span stretched back to 0
    and the last cut at the old end: a known timing error, to bound an aligner's against."""
    from dataclasses import replace

    end = spans[-1].end
    moved = [
        replace(s, start=min(s.start + delay, end), end=min(s.end + delay, end)) for s in spans
    ]
    moved[0] = replace(moved[0], start=0.0)
    return [s for s in moved if s.end > s.start]


REMOVED = object()
"""``edit_hyperparameters``'s value for a hyperparameter to delete."""


def edit_hyperparameters(model_dir: Path, **changes: Any) -> Path:
    """Rewrite the manifest of the model saved in ``model_dir``: each named hyperparameter
    set to its value, or deleted for ``REMOVED`` (a model written before it existed; a
    KeyError if the manifest lacks it). Returns the manifest's path."""
    from lipstream.store import MANIFEST_NAME

    path = model_dir / MANIFEST_NAME
    manifest = json.loads(path.read_text())
    for name, value in changes.items():
        if value is REMOVED:
            del manifest["hyperparameters"][name]
        else:
            manifest["hyperparameters"][name] = value
    path.write_text(json.dumps(manifest))
    return path
