"""Metrics tallied on the streaming path and folded later read as if observed one by one."""

from __future__ import annotations

import math

import pytest
from prometheus_client import CollectorRegistry, Counter, Histogram

from lipstream.server.metrics import LATENCY_BUCKETS_S, Metrics
from lipstream.server.tally import HistogramTally, StreamTally


def _samples(registry: CollectorRegistry) -> list[tuple[str, dict[str, str], float]]:
    """Every sample but the creation times (the two registries were made apart)."""
    return [
        (sample.name, sample.labels, sample.value)
        for family in registry.collect()
        for sample in family.samples
        if not sample.name.endswith("_created")
    ]


VALUES = [0.0, 0.001, 0.0011, 0.0025, 0.003, 0.2, 0.25, 0.26, 9.99, 10.0, 10.5, 1e6]


def _pair() -> tuple[CollectorRegistry, Histogram, CollectorRegistry, Histogram]:
    direct_registry, folded_registry = CollectorRegistry(), CollectorRegistry()
    direct = Histogram("lag", "", ["engine"], buckets=LATENCY_BUCKETS_S, registry=direct_registry)
    folded = Histogram("lag", "", ["engine"], buckets=LATENCY_BUCKETS_S, registry=folded_registry)
    return direct_registry, direct, folded_registry, folded


def test_a_folded_histogram_reads_as_the_same_values_observed_one_by_one() -> None:
    direct_registry, direct, folded_registry, folded = _pair()
    tally = HistogramTally(LATENCY_BUCKETS_S)
    for value in VALUES:
        direct.labels("e").observe(value)
        tally.observe(value)
    tally.fold(folded.labels("e"))
    assert _samples(folded_registry) == _samples(direct_registry)
    # Folded once: a second fold adds nothing, new values add on.
    tally.fold(folded.labels("e"))
    tally.observe(0.004)
    direct.labels("e").observe(0.004)
    tally.fold(folded.labels("e"))
    assert _samples(folded_registry) == _samples(direct_registry)


def test_bucket_edges_count_as_prometheus_counts_them() -> None:
    tally = HistogramTally((1.0, 2.0))
    for value in (1.0, math.nextafter(1.0, 2.0), 2.0, 3.0):
        tally.observe(value)
    assert tally.counts == [1, 2, 1]


def test_the_stream_tally_folds_counters_and_histograms_by_label() -> None:
    registry = CollectorRegistry()
    messages = Counter("messages", "", ["type"], registry=registry)
    frames = Counter("frames", "", ["engine"], registry=registry)
    lag = Histogram("lag", "", ["engine"], buckets=LATENCY_BUCKETS_S, registry=registry)
    receive = Histogram("receive", "", buckets=LATENCY_BUCKETS_S, registry=registry)
    tally = StreamTally(LATENCY_BUCKETS_S)
    for kind in ("start", "phonemes", "phonemes", "end"):
        tally.message(kind)
    tally.frames_sent("a", 3, 0.002)
    tally.frames_sent("a", 4, None)
    tally.frames_sent("b", 1, 0.5)
    tally.receive_lag.observe(0.03)

    def fold() -> None:
        tally.fold(messages.labels, frames.labels, lag.labels, receive)

    fold()
    fold()  # nothing new: nothing added
    assert registry.get_sample_value("messages_total", {"type": "phonemes"}) == 2
    assert registry.get_sample_value("messages_total", {"type": "end"}) == 1
    assert registry.get_sample_value("frames_total", {"engine": "a"}) == 7
    assert registry.get_sample_value("frames_total", {"engine": "b"}) == 1
    assert registry.get_sample_value("lag_count", {"engine": "a"}) == 1
    assert registry.get_sample_value("lag_bucket", {"engine": "b", "le": "0.25"}) == 0
    assert registry.get_sample_value("lag_bucket", {"engine": "b", "le": "0.5"}) == 1
    assert registry.get_sample_value("receive_sum", {}) == pytest.approx(0.03)


def test_a_scrape_folds_the_tally_first() -> None:
    metrics = Metrics()
    metrics.tally.message("phonemes")
    metrics.tally.frames_sent("viseme-lerp", 5, 0.01)
    text = metrics.render()[0].decode()
    assert 'lipstream_messages_received_total{type="phonemes"} 1.0' in text
    assert 'lipstream_frames_total{engine="viseme-lerp"} 5.0' in text
    assert 'lipstream_frame_lag_seconds_count{engine="viseme-lerp"} 1.0' in text


def test_infinite_bounds_are_refused() -> None:
    with pytest.raises(ValueError, match="implied"):
        StreamTally((1.0, math.inf))
