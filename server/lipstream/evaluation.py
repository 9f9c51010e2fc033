"""Quality measures on held-out utterances: RMS error and bilabial closure.

RMS error is taken over every frame and channel of an utterance, against the
recorded curves on the same time grid. Closure follows ARKit semantics: the
lips are apart by ``jawOpen - mouthClose``. A /p b m/ span counts as closed
when the smallest aperture inside it falls below a threshold learned from the
recordings: a tenth of the median aperture at the centres of open vowels.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np

from .timeline import PhonemeSpan

BILABIALS = frozenset({"P", "B", "M"})
OPEN_VOWELS = frozenset({"AA", "AE", "AH", "AO", "AW", "AY", "EH"})
CLOSURE_FRACTION = 0.1


def rms_error(predicted: np.ndarray, recorded: np.ndarray) -> float:
    """Root mean square over frames and channels; both (n_frames, n_channels)."""
    n = min(len(predicted), len(recorded))
    difference = predicted[:n].astype(np.float64) - recorded[:n].astype(np.float64)
    return float(np.sqrt(np.mean(difference**2)))


def lip_aperture(frames: np.ndarray, channels: Sequence[str]) -> np.ndarray | None:
    """``jawOpen - mouthClose`` per frame, or None when the rig lacks either channel."""
    if "jawOpen" not in channels or "mouthClose" not in channels:
        return None
    jaw = frames[:, list(channels).index("jawOpen")]
    close = frames[:, list(channels).index("mouthClose")]
    return np.asarray(jaw - close, dtype=np.float64)


def _frame_range(span: PhonemeSpan, fps: float, n_frames: int) -> slice:
    first = int(np.ceil(span.start * fps))
    stop = min(int(np.ceil(span.end * fps)), n_frames)
    return slice(first, max(first, stop))


def closure_threshold(
    recordings: Iterable[tuple[np.ndarray, Sequence[PhonemeSpan]]], fps: float
) -> float:
    """Threshold from recorded apertures (n_frames,) and their phone spans."""
    centres = [
        aperture[min(round(span.centre * fps), len(aperture) - 1)]
        for aperture, spans in recordings
        for span in spans
        if span.phoneme in OPEN_VOWELS
    ]
    if not centres:
        raise ValueError("no open vowels in the recordings: cannot learn a closure threshold")
    return CLOSURE_FRACTION * float(np.median(centres))


def closure_counts(
    aperture: np.ndarray, spans: Sequence[PhonemeSpan], fps: float, threshold: float
) -> tuple[int, int]:
    """(closed, total) over the /p b m/ spans that hold at least one frame."""
    closed = total = 0
    for span in spans:
        if span.phoneme not in BILABIALS:
            continue
        window = aperture[_frame_range(span, fps, len(aperture))]
        if len(window) == 0:
            continue
        total += 1
        closed += int(window.min() <= threshold)
    return closed, total


LAG_WINDOW_S = 0.1
"""How far around a /p b m/ span the closure is looked for: real lips close before the
acoustic onset, and a model that does not anticipate closes after it."""


PLATEAU_FRACTION = 0.05
"""A closure's plateau: the frames around the window's minimum within this share of the
window's range above it. Recorded lips rest shut for several frames while a smooth
prediction dips once, so both are timed at their plateau's centre, never at its first
frame."""


def closure_plateau(window: np.ndarray) -> tuple[int, int]:
    """The first and last frame of the plateau around the window's minimum (the first
    minimum on ties): the run of consecutive frames within ``PLATEAU_FRACTION`` of the
    window's range above the minimum."""
    lowest = int(np.argmin(window))
    level = window[lowest] + PLATEAU_FRACTION * (float(np.max(window)) - window[lowest])
    first = last = lowest
    while first > 0 and window[first - 1] <= level:
        first -= 1
    while last < len(window) - 1 and window[last + 1] <= level:
        last += 1
    return first, last


def closure_centre(window: np.ndarray) -> float:
    """The centre (in frames from the window's start) of ``closure_plateau``."""
    first, last = closure_plateau(window)
    return (first + last) / 2.0


def closure_lags(
    recorded: np.ndarray,
    predicted: np.ndarray,
    spans: Sequence[PhonemeSpan],
    fps: float,
    window_s: float = LAG_WINDOW_S,
) -> list[float]:
    """Per /p b m/ span, the time (s) of the predicted aperture's closure less the recorded
    aperture's, both within the span widened by ``window_s`` each side and both timed at
    the centre of their plateau (``closure_centre``); positive when the prediction closes
    late."""
    n_frames = min(len(recorded), len(predicted))
    lags = []
    for span in spans:
        if span.phoneme not in BILABIALS:
            continue
        first = max(0, int(np.ceil((span.start - window_s) * fps)))
        stop = min(int(np.ceil((span.end + window_s) * fps)), n_frames)
        if stop <= first:
            continue
        shift = closure_centre(predicted[first:stop]) - closure_centre(recorded[first:stop])
        lags.append(shift / fps)
    return lags
