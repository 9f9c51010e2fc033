"""The retarget cost bench on the trained test models: a row per offered preset, both paths
timed, and its scipy path the map's controls as scipy's per-frame NNLS gives them."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import nnls

from lipstream.bench.retarget_cost import main, scipy_apply, sentence
from lipstream.engines.base import Model
from lipstream.output.rig_presets import model_maps, offered_presets


def test_the_scipy_path_is_nnls_frame_by_frame(trained_models: dict[str, Model]) -> None:
    model = trained_models["viseme-lerp"]
    retarget = model_maps(model, None, only="vrm1")["vrm1"]
    frames = sentence(model)[::7]
    pairs = retarget.pairs
    system = (pairs.source_keys - pairs.source_rest).T
    blends = np.array([nnls(system, frame - pairs.source_rest)[0] for frame in frames])
    expected = np.clip(
        pairs.control_rest + blends @ (pairs.control_keys - pairs.control_rest), 0, 1
    )
    np.testing.assert_allclose(scipy_apply(retarget, frames), expected, atol=1e-9)


def test_the_command_writes_a_row_for_each_offered_preset(
    lerp_dir: Path,
    trained_models: dict[str, Model],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    out = tmp_path / "retarget.json"
    model = trained_models["viseme-lerp"]
    argv = ["--models", str(lerp_dir), "--character", model.name, "--passes", "1"]
    main([*argv, "--block", "4", "--json", str(out)])
    written = json.loads(out.read_text())
    assert written["command"].startswith("python -m lipstream.bench.retarget_cost --models")
    rows = written["rows"]
    assert [row["preset"] for row in rows] == list(offered_presets(model.channels))
    for row in rows:
        assert row["engine"] == "viseme-lerp" and row["frames"] > 0
        assert row["scipy_us"] > 0 and row["compiled_us"] > 0
        assert row["ratio"] == pytest.approx(row["scipy_us"] / row["compiled_us"], abs=0.06)
    assert "vrm1" in capsys.readouterr().out
