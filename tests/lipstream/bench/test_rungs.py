"""The per-rung bench figures, recomputed directly on the small demo corpus."""

from __future__ import annotations

import numpy as np
import pytest

from lipstream.bench.closure import learned_threshold
from lipstream.bench.harness import BASELINE, run_bench
from lipstream.bench.rungs import RungRow, format_rungs, rung_rows
from lipstream.corpus import Corpus
from lipstream.engines.base import Model


def _rms(a: np.ndarray, b: np.ndarray) -> float:
    n = min(len(a), len(b))
    return float(np.sqrt(np.mean((a[:n] - b[:n]) ** 2)))


@pytest.fixture(scope="module")
def rows(trained_models: dict[str, Model], small_demo_corpus: Corpus) -> list[RungRow]:
    train, heldout = small_demo_corpus.split()
    return rung_rows(trained_models[BASELINE], heldout, learned_threshold(train))


def test_one_row_per_rung_best_first_with_its_real_time_wait(rows: list[RungRow]) -> None:
    assert [row.rung for row in rows] == ["lerp", "damped_lead", "causal"]
    # One phoneme at the server's default 200 ms, the filter's lag, nothing.
    assert rows[0].lookahead_ms == 200.0 and rows[2].lookahead_ms == 0.0
    assert 0.0 < rows[1].lookahead_ms <= 120.0


def test_rms_against_the_recordings_and_the_best_rung(
    rows: list[RungRow],
    trained_models: dict[str, Model],
    small_demo_corpus: Corpus,
) -> None:
    model = trained_models[BASELINE]
    _, heldout = small_demo_corpus.split()
    best = [model.synthesize(u.phones, fps=heldout.fps).frames for u in heldout.utterances]
    causal = [
        model.synthesize(u.phones, fps=heldout.fps, mode="damped", lead_ms=0).frames
        for u in heldout.utterances
    ]
    recorded = [u.frames for u in heldout.utterances]
    assert rows[0].rms_vs_best == 0.0
    assert rows[0].rms_error == pytest.approx(np.mean([_rms(p, r) for p, r in zip(best, recorded)]))
    assert rows[-1].rms_error == pytest.approx(
        np.mean([_rms(p, r) for p, r in zip(causal, recorded)])
    )
    assert rows[-1].rms_vs_best == pytest.approx(
        np.mean([_rms(p, b) for p, b in zip(causal, best)])
    )
    assert rows[-1].rms_vs_best > 0.0
    assert all(row.closure_rate is not None and 0.0 <= row.closure_rate <= 1.0 for row in rows)


def test_the_bench_reports_every_rung_beside_the_engine_table(small_demo_corpus: Corpus) -> None:
    results = run_bench(small_demo_corpus, [BASELINE], engine_benches=False)
    assert [row["rung"] for row in results["rungs"]][-1] == "causal"
    engine = results["engines"][0]
    assert results["rungs"][0]["rms_error"] == pytest.approx(engine["rms_error"])
    assert results["rungs"][0]["closure_rate"] == pytest.approx(engine["closure_rate"])
    table = format_rungs(results["rungs"])
    assert "damped_lead" in table and "RMS to best" in table
