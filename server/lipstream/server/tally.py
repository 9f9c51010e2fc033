"""The streaming path's per-message metrics, kept as plain numbers and folded in batches.

Sketch: every client message and every ``frames`` block used to update prometheus
metrics at once: a counter of messages by type, the receive-lag histogram, the frames
counter and the frame-lag histogram of the engine, each update taking the metric's lock
(and, with several workers, writing its memory-mapped file). ``StreamTally`` keeps
those four as plain integers and bucket counts instead, touched only on the event
loop's thread, and ``fold`` adds what gathered since the last fold to the prometheus
metrics in one update per label and bucket. The server folds on every load-monitor
tick (every 0.1 s: what another worker's scrape sees is at most that old), before
rendering ``/metrics`` (so a scrape answered by this process is exact) and when a
connection ends. A bucket is the first whose upper bound is at least the value, as
prometheus_client counts it.
"""

from __future__ import annotations

import math
from bisect import bisect_left
from collections.abc import Callable, Sequence
from typing import Any

Child = Any
"""A labelled prometheus_client metric (``Metrics.labelled``)."""


class HistogramTally:
    """Observations not yet folded: counts per bucket (the last one +Inf) and their sum."""

    __slots__ = ("bounds", "counts", "total", "observed")

    def __init__(self, bounds: Sequence[float]) -> None:
        self.bounds = tuple(bounds)
        self.counts = [0] * (len(self.bounds) + 1)
        self.total = 0.0
        self.observed = False

    def observe(self, value: float) -> None:
        self.counts[bisect_left(self.bounds, value)] += 1
        self.total += value
        self.observed = True

    def fold(self, child: Child) -> None:
        """Add the observations to the prometheus histogram ``child`` (whose buckets are
        ``bounds`` and +Inf) and forget them."""
        if not self.observed:
            return
        add_to_histogram(child, self.counts, self.total)
        self.counts = [0] * len(self.counts)
        self.total = 0.0
        self.observed = False


def add_to_histogram(child: Child, counts: Sequence[int], total: float) -> None:
    """Add ``counts[i]`` observations to bucket i of the prometheus histogram ``child`` and
    ``total`` to its sum: what as many ``observe`` calls would add. prometheus_client has no
    public call for it; its ``_buckets`` (one value per bucket, not cumulative) and ``_sum``
    are what ``Histogram.observe`` updates, and the tests check the folded exposition
    against ``observe``'s."""
    buckets = child._buckets
    if len(buckets) != len(counts):
        raise ValueError(f"{len(counts)} bucket counts for a histogram of {len(buckets)}")
    child._sum.inc(total)
    for bucket, count in zip(buckets, counts, strict=True):
        if count:
            bucket.inc(count)


class StreamTally:
    """Messages received by type, frames sent and frame lag by engine, and the receive lag,
    gathered on the event loop's thread until ``fold``."""

    def __init__(self, bounds: Sequence[float]) -> None:
        self.bounds = tuple(bounds)
        if any(not math.isfinite(bound) for bound in self.bounds):
            raise ValueError("the finite upper bounds of the buckets; +Inf is implied")
        self.messages: dict[str, int] = {}
        self.frames: dict[str, int] = {}
        self.lag: dict[str, HistogramTally] = {}
        self.receive_lag = HistogramTally(self.bounds)

    def message(self, kind: str) -> None:
        messages = self.messages
        messages[kind] = messages.get(kind, 0) + 1

    def frames_sent(self, engine: str, frames: int, lag_s: float | None) -> None:
        self.frames[engine] = self.frames.get(engine, 0) + frames
        if lag_s is not None:
            lag = self.lag.get(engine)
            if lag is None:
                lag = self.lag[engine] = HistogramTally(self.bounds)
            lag.observe(lag_s)

    def fold(
        self,
        messages: Callable[[str], Child],
        frames: Callable[[str], Child],
        lag: Callable[[str], Child],
        receive_lag: Child,
    ) -> None:
        """Add everything gathered to the prometheus metrics (each given by its label) and
        start again from nothing."""
        for kind, count in self.messages.items():
            if count:
                messages(kind).inc(count)
                self.messages[kind] = 0
        for engine, count in self.frames.items():
            if count:
                frames(engine).inc(count)
                self.frames[engine] = 0
        for engine, histogram in self.lag.items():
            if histogram.observed:
                histogram.fold(lag(engine))
        self.receive_lag.fold(receive_lag)
