"""The bilabial lead sweep's bookkeeping on hand-made rows, and its report blocks."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from lipstream.bench.bilabial_lead_sweep import rung_options, seed_means
from lipstream.bench.closure_timing import best_lead_ms
from lipstream.bench.report import BLOCKS, Bench

RUNG_NAMES = ("full", "short", "causal_lead", "causal")


def _run(
    lead_ms: float, seed: int, lag: float, rms: float, real: float, phones: float = 0.0
) -> dict[str, Any]:
    full = {"lag_ms": lag, "closing_lag_ms": lag + 40.0, "release_lag_ms": lag - 40.0, "rms": rms}
    rungs = {
        name: {"lag_ms": lag + index, "rms": rms + index} for index, name in enumerate(RUNG_NAMES)
    }
    rungs["full"] = full
    return {
        "lead_ms": lead_ms,
        "seed": seed,
        "rungs": rungs,
        "real_phones_lag_ms": phones,
        "real": {"mean_ms": real},
    }


def test_rung_options_are_the_ladders() -> None:
    assert rung_options("full") == {"lag_ms": 500.0, "window_ms": 250.0}
    assert rung_options("causal") == {"lag_ms": 0.0, "window_ms": 0.0}


def test_seed_means_average_each_lead_over_its_seeds_and_the_pick_follows() -> None:
    rows = [
        _run(0.0, 0, 12.0, 0.066, 40.0),
        _run(0.0, 1, 8.0, 0.064, 30.0),
        _run(60.0, 0, 2.0, 0.064, 16.0),
        _run(60.0, 1, -1.0, 0.063, 12.0),
        _run(80.0, 0, 0.0, 0.070, 10.0),
        _run(80.0, 1, 0.0, 0.068, 10.0),
    ]
    means = seed_means(rows)
    assert [row["lead_ms"] for row in means] == [0.0, 60.0, 80.0]
    assert means[0]["seeds"] == 2
    assert means[0]["lag_ms"] == pytest.approx(10.0)
    assert means[0]["closing_lag_ms"] == pytest.approx(50.0)
    assert means[1]["rms"] == pytest.approx(0.0635)
    assert means[1]["rungs"]["short"]["lag_ms"] == pytest.approx(1.5)
    assert means[1]["real_lag_ms"] == pytest.approx(14.0)
    # 80 ms is on time but its RMS (0.069) is above the unled 0.065: 60 ms (+0.5)
    assert best_lead_ms(means) == 60.0


def test_seed_means_average_the_lag_on_the_real_phones_and_the_pick_weighs_it() -> None:
    rows = [
        _run(0.0, 0, 12.0, 0.066, 40.0, phones=30.0),
        _run(0.0, 1, 8.0, 0.064, 30.0, phones=20.0),
        _run(60.0, 0, 2.0, 0.064, 16.0, phones=18.0),
        _run(60.0, 1, -1.0, 0.063, 12.0, phones=10.0),
        _run(80.0, 0, 6.0, 0.064, 10.0, phones=9.0),
        _run(80.0, 1, 4.0, 0.063, 10.0, phones=5.0),
    ]
    means = seed_means(rows)
    assert [row["real_phones_lag_ms"] for row in means] == pytest.approx([25.0, 14.0, 7.0])
    # 60 ms is nearer on the held-out lines (+0.5 against +5), 80 ms on the real phones
    # (+7 against +14): the larger of the two is least at 80 ms
    assert best_lead_ms(means) == 80.0


def test_the_blocks_render_the_hmm_sweep_and_each_evaluated_engine(tmp_path: Path) -> None:
    means = seed_means(
        [_run(0.0, 0, 10.0, 0.065, 37.0, 36.25), _run(60.0, 0, 0.75, 0.0639, 15.0, 14.5)]
    )
    evaluated = [
        {
            "lead_ms": lead,
            "lag_ms": lag,
            "closing_lag_ms": lag + 30.0,
            "release_lag_ms": lag - 30.0,
            "rms": rms,
            "real_phones_lag_ms": real - 0.75,
            "real": {"mean_ms": real},
        }
        for lead, lag, rms, real in ((0.0, 7.25, 0.06514, 16.5), (10.0, 3.25, 0.06523, 13.5))
    ]
    doc = {
        "date": "2030-01-02T03:04:05+00:00",
        "corpus": {"name": "demo", "fps": 120.0},
        "real_set": {"name": "grid", "clips": 59, "fps": 25.0},
        "rungs": list(RUNG_NAMES),
        "engines": {
            "hmm": {
                "seeds": [0],
                "leads": means,
                "best_lead_ms": 60.0,
                "chosen_lead_ms": 60.0,
            },
            "anime-graph": {"leads": evaluated, "best_lead_ms": 0.0},
            "expressive-dp": {"leads": evaluated, "best_lead_ms": 0.0},
        },
    }
    (tmp_path / "bilabial_lead_sweep.json").write_text(json.dumps(doc))
    hmm = BLOCKS["bilabial-lead-hmm"](Bench(tmp_path))
    assert "Source: `bench/bilabial_lead_sweep.json`" in hmm
    assert "| **60** | +0.8 | +40.8 | -39.2 | 0.06390 | +1.8 / 1.0639 |" in hmm
    assert "| 0 | +10.0 | +50.0 | -30.0 | 0.06500 |" in hmm
    assert "| +36.2 | +37.0 |" in hmm and "59 clips of `grid`" in hmm
    assert "behind the character on the real phones (`full`, means over the seeds): 60 ms" in hmm
    assert "(default 60 ms)" in hmm
    for engine in ("anime-graph", "expressive-dp"):
        rendered = BLOCKS[f"bilabial-lead-{engine}"](Bench(tmp_path))
        assert f"`{engine}` trained on" in rendered
        assert "| 10 | +3.2 | +33.2 | -26.8 | 0.06523 | +12.8 | +13.5 |" in rendered
        assert "behind the character on the real phones: 0 ms." in rendered


def test_the_blocks_say_when_the_sweep_was_not_run(tmp_path: Path) -> None:
    for name in ("bilabial-lead-hmm", "bilabial-lead-anime-graph"):
        assert "no `bench/bilabial_lead_sweep.json`" in BLOCKS[name](Bench(tmp_path))
