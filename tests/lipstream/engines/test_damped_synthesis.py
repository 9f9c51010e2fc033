"""The damped rung's merged, compiled stepping against the plain sort-and-step computation.

The reference lists every piece boundary offline (all frame times and every target step
between them, sorted, equal times once), then steps ``DampedState`` through the pieces one
by one with the target of the span holding at each piece's start: the method in the module
docstring, written out without the streaming bookkeeping.
"""

from __future__ import annotations

from bisect import bisect_right

import numpy as np
import pytest

from lipstream.engines.base import SynthesisRequest, frame_count
from lipstream.engines.damped import DampedState
from lipstream.engines.damped_synthesis import DampedTargets, DampedTimelineSynthesizer
from lipstream.phonemes import PHONEME_INDEX, PHONEMES, SILENCE
from lipstream.timeline import PhonemeSpan

N_CHANNELS = 3


def _spans(rng: np.random.Generator, fps: float, count: int) -> list[PhonemeSpan]:
    """Random spans with gaps; half the boundaries on the frame grid, so steps meet frames."""
    spans, t = [], 0.0
    for _ in range(count):
        start = t + (float(rng.uniform(0.0, 0.1)) if rng.random() < 0.2 else 0.0)
        end = start + float(rng.uniform(0.01, 0.2))
        if rng.random() < 0.5:
            end = max(np.ceil(end * fps), np.floor(start * fps) + 1) / fps
            start = min(start, end - 1e-3)
        spans.append(PhonemeSpan(PHONEMES[int(rng.integers(len(PHONEMES)))], start, end))
        t = end
    return spans


def _reference(
    targets: DampedTargets, spans: list[PhonemeSpan], fps: float
) -> tuple[np.ndarray, DampedState]:
    """The frames (float64) and the filter's state after the last."""
    filled, cursor = [], 0.0
    for span in spans:
        if span.start > cursor + 1e-9:
            filled.append(PhonemeSpan(SILENCE, cursor, span.start))
        filled.append(span)
        cursor = span.end
    shifted = [span.start - targets.lead_s for span in filled]
    rows = [PHONEME_INDEX[span.phoneme] for span in filled]
    times = [k / fps for k in range(frame_count(cursor, fps))]

    def row_at(t: float) -> int:
        return rows[max(0, bisect_right(shifted, t) - 1)]

    state = DampedState.at_rest(targets.poses[row_at(0.0)])
    frames = [state.x.copy()]
    frame_times = set(times[1:])
    points = sorted(frame_times | {s for s in shifted if 0.0 < s < times[-1]})
    omegas = np.repeat(targets.omegas[:, None], N_CHANNELS, axis=1)
    previous = 0.0
    for point in points:
        row = row_at(previous)
        state.step(targets.poses[row], omegas[row], point - previous)
        previous = point
        if point in frame_times:
            frames.append(state.x.copy())
    return np.asarray(frames), state


@pytest.mark.parametrize("seed", range(6))
def test_streamed_frames_equal_the_plain_piecewise_stepping(seed: int) -> None:
    rng = np.random.default_rng(seed)
    fps = float(rng.choice([24.0, 30.0, 60.0, 100.0]))
    lead_s = float(rng.choice([0.0, 0.03, 0.12]))
    targets = DampedTargets(
        rng.normal(size=(len(PHONEMES), N_CHANNELS)), rng.uniform(5.0, 80.0, len(PHONEMES)), lead_s
    )
    spans = _spans(rng, fps, 40)
    chunking = rng.integers(1, 4, size=len(spans))
    channels = tuple(f"c{i}" for i in range(N_CHANNELS))
    emitted = DampedTimelineSynthesizer(targets, SynthesisRequest(fps=fps), channels)
    stepped = DampedTimelineSynthesizer(targets, SynthesisRequest(fps=fps), channels)
    chunks, exact, fed = [], [], 0
    for size in chunking:
        emitted.feed(spans[fed : fed + size])
        stepped.feed(spans[fed : fed + size])
        fed += size
        chunks.append(emitted.frames())
        reach = stepped.covered_until - lead_s
        if reach >= 0.0:
            exact.append(stepped.advance_to(frame_count(reach, fps)))
    chunks.append(emitted.finish())
    exact.append(stepped.advance_to(frame_count(stepped.covered_until, fps)))
    expected, state = _reference(targets, spans, fps)
    # float64, bit for bit: a zero-length step or a piece cut differently changes the last
    # bits, which float32 frames hide
    assert np.array_equal(np.concatenate(exact), expected)
    assert np.array_equal(np.concatenate(chunks), expected.astype(np.float32))
    assert emitted.state is not None
    assert np.array_equal(emitted.state.x, state.x) and np.array_equal(emitted.state.v, state.v)
