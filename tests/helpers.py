"""Test helpers shared across test modules (imported as ``helpers``)."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np

    from lipstream.engines.base import Model

REPO = Path(__file__).resolve().parents[1]
# Real Live Link Face exports, when present: .ci/run points it at ../shared/data/livelink-face.
LIVELINK_DIR_VARIABLE = "LIPSTREAM_LIVELINK_DIR"


def real_livelink_takes() -> list[Path]:
    """The ``*.csv`` exports in ``$LIPSTREAM_LIVELINK_DIR``; none when the variable is unset."""
    directory = os.environ.get(LIVELINK_DIR_VARIABLE, "").strip()
    return sorted(Path(directory).glob("*.csv")) if directory else []


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
