"""``lipstream bench`` figures recomputed independently on the small demo corpus."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from lipstream.bench.harness import BASELINE, format_table, run_bench
from lipstream.corpus import Corpus
from lipstream.engines import engine_names
from lipstream.engines.viseme_lerp import VisemeLerpEngine


@pytest.fixture(scope="module")
def results(small_demo_corpus: Corpus) -> dict[str, Any]:
    return run_bench(
        small_demo_corpus, [BASELINE], engine_benches=False, command="lipstream bench --x"
    )


def test_the_results_say_how_they_were_made(results: dict[str, Any]) -> None:
    assert results["command"] == "lipstream bench --x"
    assert {"date", "machine", "lipstream_version"} <= results.keys()


def test_baseline_rms_matches_a_direct_computation(
    results: dict[str, Any], small_demo_corpus: Corpus
) -> None:
    train, heldout = small_demo_corpus.split()
    model = VisemeLerpEngine().fit(train)
    errors = []
    for utterance in heldout.utterances:
        frames = model.synthesize(utterance.phones, fps=heldout.fps).frames
        n = min(len(frames), len(utterance.frames))
        errors.append(np.sqrt(np.mean((frames[:n] - utterance.frames[:n]) ** 2)))
    row = results["engines"][0]
    assert row["engine"] == BASELINE
    assert row["rms_error"] == pytest.approx(float(np.mean(errors)), rel=1e-6)
    assert row["rms_ratio"] == 1.0 and row["speed_ratio"] == 1.0


def test_recorded_closure_and_threshold_are_reported(results: dict[str, Any]) -> None:
    recorded = results["recorded"]
    assert 0.0 < recorded["closure_threshold"] < 0.05
    assert recorded["closure_rate"] == pytest.approx(1.0, abs=0.1)
    assert results["corpus"]["heldout_utterances"] >= 2


def test_table_names_every_engine_benchmarked(results: dict[str, Any]) -> None:
    table = format_table(results)
    assert table.splitlines()[2].startswith(BASELINE)
    assert "recorded" in table.splitlines()[-1]
    assert set(engine_names()) >= {row["engine"] for row in results["engines"]}


def test_rms_per_emotion_is_the_mean_of_each_emotions_lines(
    results: dict[str, Any], small_demo_corpus: Corpus
) -> None:
    _, heldout = small_demo_corpus.split()
    row = results["engines"][0]
    emotions = sorted({u.emotion for u in heldout.utterances})
    assert sorted(row["rms_by_emotion"]) == emotions
    weights = [sum(u.emotion == e for u in heldout.utterances) for e in emotions]
    weighted = sum(w * row["rms_by_emotion"][e] for w, e in zip(weights, emotions, strict=True))
    assert weighted / len(heldout.utterances) == pytest.approx(row["rms_error"], rel=1e-9)
