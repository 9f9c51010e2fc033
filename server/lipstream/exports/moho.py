"""Moho (and OpenToonz) switch data, ``.dat``, as Rhubarb Lip Sync's ``-f dat`` writes it.

Sketch: the line ``MohoSwitch1``, then one ``frame shape`` line per mouth cue,
where frame = 1 + floor(fps * start) counts from 1 at the Moho project's
frame rate (24 by default, as Rhubarb's ``--datFrameRate``); a cue landing on
the frame of the one before it is left out (the earlier cue keeps the
frame). A last line closes the mouth (``X``) at the end's frame, one frame
later if that frame is taken. Shapes keep their letters A-H and X.
"""

from __future__ import annotations

import math

from ..errors import InvalidRequestError
from .cues import REST_SHAPE, MouthCues
from .formats import MOHO_FPS

MIN_MOHO_FPS, MAX_MOHO_FPS = 24.0, 100.0
_EPS = 1e-9


def moho_dat(cues: MouthCues, fps: float = MOHO_FPS) -> str:
    if not MIN_MOHO_FPS <= fps <= MAX_MOHO_FPS:
        raise InvalidRequestError(
            f"the Moho frame rate must be in [{MIN_MOHO_FPS:g}, {MAX_MOHO_FPS:g}], got {fps:g}",
            where="moho_fps",
        )
    lines = ["MohoSwitch1"]
    last = 0
    for cue in cues.cues:
        frame = _frame(cue.start, fps)
        if frame == last:
            continue
        lines.append(f"{frame} {cue.value}")
        last = frame
    end = _frame(cues.end, fps)
    lines.append(f"{end + 1 if end == last else end} {REST_SHAPE}")
    return "\n".join(lines) + "\n"


def _frame(centiseconds: int, fps: float) -> int:
    return 1 + math.floor(fps * centiseconds / 100 + _EPS)
