"""The load test's statistics against direct counts."""

from __future__ import annotations

import random

from lipstream.loadtest.stats import peak_overlap


def _covering(spans: list[tuple[float, float]], instant: float) -> int:
    return sum(start <= instant < end for start, end in spans)


def test_peak_overlap_is_the_most_spans_covering_any_start() -> None:
    rng = random.Random(7)
    for _ in range(200):
        spans = []
        for _ in range(rng.randrange(1, 30)):
            start = rng.randrange(0, 40) / 4
            spans.append((start, start + rng.randrange(1, 20) / 4))
        # half-open spans: the most at once is reached at some span's start
        assert peak_overlap(iter(spans)) == max(_covering(spans, start) for start, _ in spans)


def test_spans_that_touch_do_not_overlap() -> None:
    assert peak_overlap([(0.0, 1.0), (1.0, 2.0), (2.0, 3.0)]) == 1
    assert peak_overlap([(0.0, 1.0), (0.5, 2.0), (0.9, 1.0)]) == 3
    assert peak_overlap([]) == 0
