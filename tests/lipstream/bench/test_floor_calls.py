"""The floor-call bench on the trained test models: one row per engine, counted calls."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from lipstream.bench.floor_calls import call_costs, main, measure
from lipstream.engines.base import Model


def test_each_call_is_timed_and_the_median_lies_within_the_calls(
    trained_models: dict[str, Model],
) -> None:
    model = trained_models["viseme-lerp"]
    costs = call_costs(model, 12)
    assert len(costs) == 12 and all(cost >= 0.0 for cost in costs)
    row = measure(model, calls=10, passes=2)
    assert (row.engine, row.rung, row.calls) == ("viseme-lerp", "causal", 20)
    assert 0.0 <= row.median_us <= row.p90_us and row.mean_us > 0.0


def test_the_command_writes_a_row_for_each_engine_of_the_character(
    lerp_dir: Path,
    trained_models: dict[str, Model],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    out = tmp_path / "floor.json"
    character = trained_models["viseme-lerp"].name
    argv = [
        "--models",
        str(lerp_dir),
        "--character",
        character,
        "--calls",
        "5",
        "--passes",
        "2",
        "--json",
        str(out),
    ]
    main(argv)
    written = json.loads(out.read_text())
    assert written["command"] == "python -m lipstream.bench.floor_calls " + " ".join(argv)
    assert written["date"].startswith("20") and written["machine"]["cores"] >= 1
    rows = written["rows"]
    assert [(row["engine"], row["calls"]) for row in rows] == [("viseme-lerp", 10)]
    assert "viseme-lerp" in capsys.readouterr().out


def test_every_rung_gets_a_row_with_all_rungs(
    lerp_dir: Path,
    trained_models: dict[str, Model],
    tmp_path: Path,
) -> None:
    out = tmp_path / "rungs.json"
    model = trained_models["viseme-lerp"]
    main(
        [
            "--models",
            str(lerp_dir),
            "--character",
            model.name,
            "--calls",
            "4",
            "--passes",
            "1",
            "--all-rungs",
            "--json",
            str(out),
        ]
    )
    rows = json.loads(out.read_text())["rows"]
    assert [row["rung"] for row in rows] == [rung.name for rung in model.fidelity_ladder()]
    assert all(row["calls"] == 4 for row in rows)
