"""The compiled interpolation of ``viseme-lerp`` against ``np.interp`` per channel."""

from __future__ import annotations

import numpy as np
import pytest

from lipstream.engines.lerp_keys import KeyedSpans, lerp_frames
from lipstream.phonemes import PHONEMES
from lipstream.timeline import PhonemeSpan

N_CHANNELS = 5


def _keys(generator: np.random.Generator, count: int) -> tuple[KeyedSpans, np.ndarray]:
    """``count`` contiguous spans of random phonemes and lengths, and random float32 poses
    (one row per phoneme, so the phoneme index is the pose row)."""
    ends = np.cumsum(generator.uniform(0.02, 0.3, count))
    starts = np.concatenate([[0.0], ends[:-1]])
    labels = generator.integers(0, len(PHONEMES), count)
    spans = KeyedSpans(
        [
            PhonemeSpan(PHONEMES[label], float(start), float(end))
            for label, start, end in zip(labels, starts, ends, strict=True)
        ]
    )
    poses = generator.normal(size=(len(PHONEMES), N_CHANNELS)).astype(np.float32)
    return spans, poses


def _interp(spans: KeyedSpans, poses: np.ndarray, times: np.ndarray) -> np.ndarray:
    centres = np.array([(span.start + span.end) / 2 for span in spans])
    keys = poses[[PHONEMES.index(span.phoneme) for span in spans]].astype(np.float64)
    columns = [np.interp(times, centres, keys[:, c]) for c in range(N_CHANNELS)]
    return np.stack(columns, axis=1).astype(np.float32)


@pytest.mark.parametrize("seed", range(6))
def test_runs_of_frames_equal_np_interp_per_channel(seed: int) -> None:
    generator = np.random.default_rng(seed)
    spans, poses = _keys(generator, int(generator.integers(1, 40)))
    rows = np.arange(len(PHONEMES))
    times = np.arange(0.0, spans[-1].end + 0.2, 1 / 60)
    expected = _interp(spans, poses, times)
    cuts = np.sort(generator.integers(0, len(times), 8))
    pieces = []
    for begin, stop in zip([0, *cuts], [*cuts, len(times)], strict=True):
        centres, phonemes = spans.keys()
        frames, spans.first_key = lerp_frames(
            centres, phonemes, rows, poses, times[begin:stop], spans.first_key
        )
        assert frames.dtype == np.float32 and frames.shape == (stop - begin, N_CHANNELS)
        pieces.append(frames)
    np.testing.assert_array_max_ulp(np.concatenate(pieces), expected, maxulp=1)
    # a run that starts before the window of the last one steps back to its keys
    early = times[: len(times) // 3]
    frames, first = lerp_frames(*spans.keys(), rows, poses, early, len(spans) - 1)
    np.testing.assert_array_max_ulp(frames, _interp(spans, poses, early), maxulp=1)
    assert first == max(0, int(np.searchsorted(spans.keys()[0], early[0], side="right")) - 1)
