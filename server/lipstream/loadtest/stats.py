"""Summary statistics of a load test, computed as Audio2Face-3D's benchmark computes them.

Sketch: NVIDIA's ``nim_performance_test.py`` summarizes each clip length by
the min, 1st, 5th, 10th percentiles, median, mean, 90th, 95th and 99th
percentiles and max of the per-request first-packet latency and of the
per-stream fps, with NumPy's default percentile (linear interpolation
between closest ranks: the q-th percentile of n sorted values sits at
fractional rank q/100 * (n - 1)). It then reports the worst p99 latency and
the mean of the mean latencies over all clips, and the lowest p1 fps. This
module does the same in pure Python; an empty sample gives None (JSON null)
where NumPy would give NaN.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence

# (key in the results, percentile); None marks the mean.
A2F_STATISTICS: tuple[tuple[str, float | None], ...] = (
    ("min", 0.0),
    ("p1", 1.0),
    ("p5", 5.0),
    ("p10", 10.0),
    ("p50", 50.0),
    ("mean", None),
    ("p90", 90.0),
    ("p95", 95.0),
    ("p99", 99.0),
    ("max", 100.0),
)
LAG_STATISTICS: tuple[tuple[str, float | None], ...] = (
    ("p50", 50.0),
    ("mean", None),
    ("p95", 95.0),
    ("p99", 99.0),
    ("max", 100.0),
)

Summary = dict[str, float | None]


def percentile(sorted_values: Sequence[float], q: float) -> float:
    """The ``q``-th percentile (0..100) of ascending ``sorted_values`` by linear
    interpolation, as ``numpy.percentile``'s default; ValueError when empty."""
    if not sorted_values:
        raise ValueError("percentile of an empty sample")
    if not 0.0 <= q <= 100.0:
        raise ValueError(f"percentile must be in [0, 100], got {q}")
    rank = q / 100.0 * (len(sorted_values) - 1)
    low = math.floor(rank)
    high = min(low + 1, len(sorted_values) - 1)
    fraction = rank - low
    return sorted_values[low] + (sorted_values[high] - sorted_values[low]) * fraction


def summarize(
    values: Iterable[float], statistics: Sequence[tuple[str, float | None]] = A2F_STATISTICS
) -> Summary:
    """The named statistics of ``values``, each None when there are no values."""
    ordered = sorted(values)
    if not ordered:
        return {name: None for name, _ in statistics}
    mean = math.fsum(ordered) / len(ordered)
    return {name: mean if q is None else percentile(ordered, q) for name, q in statistics}


def peak_overlap(spans: Iterable[tuple[float, float]]) -> int:
    """The most of the (start, end) ``spans`` that cover one instant; a span that ends as
    another starts does not overlap it."""
    events: list[tuple[float, int]] = []
    for start, end in spans:
        events += [(start, 1), (end, -1)]
    events.sort()  # at equal times -1 sorts first: an end before a start
    peak = running = 0
    for _, step in events:
        running += step
        peak = max(peak, running)
    return peak


def _present(values: Iterable[float | None]) -> list[float]:
    return [value for value in values if value is not None]


def overall_summary(clips: Sequence[Mapping[str, Summary]]) -> Summary:
    """Audio2Face-3D's headline figures over all clips: the worst p99 and the mean of
    the mean first-packet latencies (ms), the lowest p1 fps, and the worst p99 and max
    frame lag (ms). None where no clip has a value."""
    worst = _present(clip["first_packet_latency_ms"]["p99"] for clip in clips)
    means = _present(clip["first_packet_latency_ms"]["mean"] for clip in clips)
    fps_floor = _present(clip["fps"]["p1"] for clip in clips)
    lag_p99 = _present(clip["frame_lag_ms"]["p99"] for clip in clips)
    lag_max = _present(clip["frame_lag_ms"]["max"] for clip in clips)
    return {
        "worst_p99_first_packet_latency_ms": max(worst) if worst else None,
        "mean_first_packet_latency_ms": math.fsum(means) / len(means) if means else None,
        "lowest_p1_fps": min(fps_floor) if fps_floor else None,
        "worst_p99_frame_lag_ms": max(lag_p99) if lag_p99 else None,
        "max_frame_lag_ms": max(lag_max) if lag_max else None,
    }
