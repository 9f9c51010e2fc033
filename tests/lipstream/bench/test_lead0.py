"""The lead-0 bench against a real server: every rung gets a row, its options select it (its
lookahead), and every frame of each paced request is counted."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from lipstream.bench.lead0 import main
from lipstream.engines.base import Model, frame_count
from lipstream.loadtest.clips import synthetic_clip
from tests.helpers import return_frames
from tests.live_server import live_server


def test_each_rung_is_served_with_its_own_lookahead_and_every_frame_is_timed(
    lerp_dir: Path,
    trained_models: dict[str, Model],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    model = trained_models["viseme-lerp"]
    out = tmp_path / "lead0.json"
    with live_server(lerp_dir) as server:
        main(
            [
                "--url",
                server.ws,
                "--models",
                str(lerp_dir),
                "--character",
                model.name,
                "--clip",
                "1.5",
                "--requests",
                "2",
                "--probes",
                "2",
                "--json",
                str(out),
            ]
        )
    written = json.loads(out.read_text())
    assert written["command"].startswith(f"python -m lipstream.bench.lead0 --url {server.ws} ")
    assert written["date"].startswith("20") and written["machine"]["cores"] >= 1
    rows = written["rows"]
    rungs = [rung.name for rung in model.fidelity_ladder()]
    assert [(row["engine"], row["rung"]) for row in rows] == [("viseme-lerp", r) for r in rungs]
    lookaheads = [row["lookahead_ms"] for row in rows]
    assert lookaheads == sorted(lookaheads, reverse=True) and lookaheads[0] > lookaheads[1]
    assert lookaheads[-1] == 0.0  # the causal rung's frames wait for no input
    frames = sum(
        frame_count(synthetic_clip(1.5, seed=k)[-1][2], 60.0) + return_frames(60.0)
        for k in range(2)
    )
    assert all(row["frames"] == frames for row in rows)
    for row in rows:
        assert row["lag_p50_ms"] <= row["lag_p99_ms"]
        assert 0.0 < row["first_frame_p50_ms"] <= row["first_frame_p99_ms"]
    assert "causal" in capsys.readouterr().out
