"""``python -m lipstream.bench.sentences``: the draws, the summaries and the split on known
inputs, the GRID speaker count against the clips' own files, and a tiny run end to end."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from lipstream.bench import sentences
from lipstream.bench.sentences import (
    Run,
    draw_sentences,
    real_speakers,
    sentence_split,
    spread,
    summarize,
)
from lipstream.errors import LipstreamError

GRID = Path(__file__).resolve().parents[2] / "data" / "grid" / "corpus"


def test_a_draw_is_the_same_for_the_same_seed_and_differs_across_draws() -> None:
    first = draw_sentences(30, 6, seed=7, draw=0)
    assert first == draw_sentences(30, 6, seed=7, draw=0)
    assert len(set(first)) == 6 and first == sorted(first)
    assert all(0 <= index < 30 for index in first)
    others = [draw_sentences(30, 6, seed=7, draw=d) for d in (1, 2, 3)]
    assert any(other != first for other in others)
    assert any(draw_sentences(30, 6, seed=seed, draw=0) != first for seed in (8, 9, 10))
    assert draw_sentences(5, 5, seed=1, draw=3) == [0, 1, 2, 3, 4]


def test_a_draw_larger_than_the_pool_is_refused() -> None:
    with pytest.raises(LipstreamError, match="pool of 4"):
        draw_sentences(4, 5, seed=0, draw=0)


def test_the_pool_and_the_heldout_sentences_never_meet() -> None:
    # the demo corpus holds out one sentence per block of ten
    pool, heldout = sentence_split(40, pool=20, heldout=3)
    assert len(pool) == 20 and len(heldout) == 3
    assert not set(pool) & set(heldout)
    assert [index // 10 for index in heldout] == [0, 1, 2]
    assert pool == sorted(pool)
    with pytest.raises(LipstreamError, match="held-out"):
        sentence_split(40, pool=20, heldout=5)


def test_spread_is_median_and_range_of_the_known_values() -> None:
    assert spread([0.3, None, 0.1, 0.7, 0.2]) == {"median": 0.25, "min": 0.1, "max": 0.7}
    assert spread([None, None]) is None


def test_summaries_group_by_engine_and_size_and_count_failures() -> None:
    runs = [
        Run("dam", 3, 0, 1.0, rms_error=0.2),
        Run("dam", 3, 1, None, error="too few"),
        Run("dam", 3, 2, 3.0, rms_error=0.4),
        Run("viseme-lerp", 3, 0, 0.5, rms_error=0.1),
    ]
    rows = {(row["engine"], row["n"]): row for row in summarize(runs)}
    dam = rows[("dam", 3)]
    assert (dam["draws"], dam["failed"]) == (3, 1)
    assert dam["rms_error"] == pytest.approx({"median": 0.3, "min": 0.2, "max": 0.4})
    assert dam["train_cpu_s"] == {"median": 2.0, "min": 1.0, "max": 3.0}
    assert dam["aperture_r"] is None
    assert rows[("viseme-lerp", 3)]["draws"] == 1


def test_the_grid_speakers_are_counted_from_the_clips_files() -> None:
    """49 clips of GRID's talker s1, ten others each their own: a curve can be drawn
    from s1 at sizes below 49, not at 49 or more."""
    clips = [path for path in GRID.glob("*.json") if path.name != "corpus.json"]
    speakers = [json.loads(path.read_text())["speaker"] for path in clips]
    found = real_speakers(GRID, smallest=3)
    assert found is not None
    assert found["clips"] == len(speakers) == 59
    assert found["speakers"] == len(set(speakers)) == 11
    assert found["most_clips_of_one_speaker"] == speakers.count("s1") == 49
    assert found["curve_possible"] is True
    assert real_speakers(GRID, smallest=49)["curve_possible"] is False  # type: ignore[index]


def test_a_tiny_run_writes_the_curve(tmp_path: Path) -> None:
    path = tmp_path / "curve.json"
    sentences.main(
        [
            "--sizes",
            "2",
            "3",
            "--draws",
            "2",
            "--engines",
            "cohen-massaro",
            "--pool",
            "4",
            "--heldout",
            "2",
            "--models",
            str(tmp_path / "no-models"),
            "--json",
            str(path),
        ]
    )
    results = json.loads(path.read_text())
    assert {"command", "date", "machine", "curve", "runs", "demo", "heldout"} <= set(results)
    assert results["engines"] == ["viseme-lerp", "cohen-massaro"]
    assert len(results["runs"]) == 2 * 2 * 2
    assert len(results["heldout"]["stems"]) == 2
    assert [len(draw) for draw in results["drawn"]["3"]] == [3, 3]
    assert not set(results["drawn"]["3"][0]) & set(results["heldout"]["stems"])
    assert results["demo"] == []
    for run in results["runs"]:
        assert run["error"] is None and run["rms_error"] > 0
        if run["engine"] == "viseme-lerp":
            assert run["rms_ratio"] == 1.0
    assert sorted((row["engine"], row["n"]) for row in results["curve"]) == [
        ("cohen-massaro", 2),
        ("cohen-massaro", 3),
        ("viseme-lerp", 2),
        ("viseme-lerp", 3),
    ]
