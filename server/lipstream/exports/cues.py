"""Mouth cues: Preston Blair shape weights per frame, as Rhubarb Lip Sync's timed shapes.

Sketch: each frame shows the shape of largest weight (the first of equal
ones, in ``A``-``H``, ``X`` order) and holds it until the next frame, so frame
i covers [i / fps, (i + 1) / fps) and n frames cover n / fps seconds. Times are
counted, as Rhubarb counts them, in whole centiseconds (rounded); a run of
frames showing one shape is one cue, and a cue that rounds to no time at all
(only above 100 fps) is dropped, its neighbours joining if they match.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from lipstream_client.channels import PRESTON_BLAIR_SHAPES

from ..errors import InvalidRequestError

REST_SHAPE = "X"


@dataclass(frozen=True)
class MouthCue:
    """Shape ``value`` from ``start`` to ``end``, in centiseconds."""

    start: int
    end: int
    value: str


@dataclass(frozen=True)
class MouthCues:
    cues: tuple[MouthCue, ...]
    end: int  # centiseconds: the end of the animation


def mouth_cues(frames: np.ndarray, channels: Sequence[str], fps: float) -> MouthCues:
    """The cues of frames (n, 9) whose ``channels`` are the nine Preston Blair shapes."""
    if sorted(channels) != sorted(PRESTON_BLAIR_SHAPES):
        raise InvalidRequestError(
            "Rhubarb and Moho exports need the nine Preston Blair shapes as channels "
            f"({', '.join(PRESTON_BLAIR_SHAPES)}), got {', '.join(channels) or 'none'}; "
            "use visemes 'preston-blair' with every channel",
            where="channels",
        )
    order = [list(channels).index(shape) for shape in PRESTON_BLAIR_SHAPES]
    weights = np.asarray(frames, dtype=np.float64)[:, order]
    shapes = [PRESTON_BLAIR_SHAPES[index] for index in np.argmax(weights, axis=1)]
    cues: list[MouthCue] = []
    for index, shape in enumerate(shapes):
        start, end = _centiseconds(index, fps), _centiseconds(index + 1, fps)
        if start == end:
            continue
        if cues and cues[-1].value == shape:
            cues[-1] = MouthCue(cues[-1].start, end, shape)
        else:
            cues.append(MouthCue(start, end, shape))
    return MouthCues(tuple(cues), _centiseconds(len(shapes), fps))


def _centiseconds(frame: int, fps: float) -> int:
    return round(frame * 100 / fps)
