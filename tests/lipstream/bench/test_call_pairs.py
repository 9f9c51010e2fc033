"""The side-by-side per-call comparison: medians over rounds, ratios and wins, by hand."""

from __future__ import annotations

from typing import Any

import pytest

from lipstream.bench.call_pairs import compare


def _run(median: float, mean: float) -> list[dict[str, Any]]:
    return [{"engine": "hmm", "rung": "causal", "median_us": median, "mean_us": mean}]


def test_medians_over_rounds_their_ratio_and_the_rounds_won() -> None:
    before = [_run(10.0, 12.0), _run(12.0, 20.0), _run(11.0, 13.0)]
    after = [_run(9.0, 11.0), _run(13.0, 12.0), _run(10.0, 14.0)]
    (row,) = compare(before, after)
    # medians of (10, 12, 11) and (9, 13, 10); of the means (12, 20, 13) and (11, 12, 14)
    assert (row["before_median_us"], row["after_median_us"]) == (11.0, 10.0)
    assert row["median_ratio"] == pytest.approx(10 / 11, abs=5e-4)
    assert (row["before_mean_us"], row["after_mean_us"]) == (13.0, 12.0)
    assert row["rounds_after_lower"] == 2 and row["rounds"] == 3
