"""``lipstream retarget`` fit/build/show and ``lipstream synth --retarget`` on real files."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pytest

from lipstream.corpus.livelink import ARKIT_BLENDSHAPES
from tests.helpers import run_cli

if TYPE_CHECKING:
    from lipstream.engines.base import Model

# The preset names the issue and the other helpers use, in the order `show` lists them.
PRESET_NAMES = (
    "oculus15",
    "arkit52",
    "vrm1",
    "vrm0",
    "vroid",
    "rpm",
    "unified",
    "metahuman",
    "a2f68",
)
PHONES = [
    {"phoneme": "sil", "start": 0.0, "end": 0.3},
    {"phoneme": "M", "start": 0.3, "end": 0.5},
    {"phoneme": "AA", "start": 0.5, "end": 0.9},
    {"phoneme": "sil", "start": 0.9, "end": 1.2},
]
PAIRS = {
    "controls": ["open", "shut"],
    "keys": [
        {"name": "open", "source": {"jawOpen": 1.0}, "controls": {"open": 1.0}},
        {"name": "shut", "source": {"mouthClose": 1.0}, "controls": {"shut": 1.0}},
    ],
}


@pytest.fixture
def lerp_model(trained_models: dict[str, Model], tmp_path: Path) -> Path:
    directory = tmp_path / "viseme-lerp"
    trained_models["viseme-lerp"].save(directory)
    return directory


def synth_json(model: Path, tmp_path: Path, *extra: str) -> dict[str, Any]:
    phones = tmp_path / "phones.json"
    phones.write_text(json.dumps(PHONES))
    out = tmp_path / f"out{len(extra)}.json"
    result = run_cli(
        "synth", "--model", str(model), "--phones", str(phones), "--out", str(out), *extra
    )
    assert result.returncode == 0, result.stderr
    data: dict[str, Any] = json.loads(out.read_text())
    return data


def fit_jaw(model: Path, tmp_path: Path) -> None:
    """``retarget fit`` of the map ``jaw`` from ``PAIRS``, stored beside ``model``."""
    pairs = tmp_path / "pairs.json"
    pairs.write_text(json.dumps(PAIRS))
    fitted = run_cli(
        "retarget", "fit", "--model", str(model), "--pairs", str(pairs), "--name", "jaw"
    )
    assert fitted.returncode == 0, fitted.stderr


def test_a_fitted_map_is_stored_beside_the_model_and_synth_serves_its_controls(
    lerp_model: Path, tmp_path: Path
) -> None:
    fit_jaw(lerp_model, tmp_path)
    assert (lerp_model / "retarget" / "jaw" / "retarget.json").is_file()
    plain = synth_json(lerp_model, tmp_path)
    mapped = synth_json(lerp_model, tmp_path, "--retarget", "jaw")
    assert mapped["channels"] == ["open", "shut"]
    raw = np.array(plain["frames"], dtype=np.float64)
    columns = [plain["channels"].index("jawOpen"), plain["channels"].index("mouthClose")]
    expected = np.clip(raw[:, columns], 0.0, 1.0)
    np.testing.assert_allclose(np.array(mapped["frames"]), expected, atol=1e-6)


def test_build_writes_a_shipped_target_and_its_pairs_and_show_lists_the_maps(
    lerp_model: Path, tmp_path: Path
) -> None:
    pairs = tmp_path / "arkit.json"
    built = run_cli(
        "retarget",
        "build",
        "--model",
        str(lerp_model),
        "--target",
        "arkit52",
        "--pairs-out",
        str(pairs),
    )
    assert built.returncode == 0, built.stderr
    written = json.loads(pairs.read_text())
    assert tuple(written["controls"]) == ARKIT_BLENDSHAPES
    assert all(len(key["controls"]) == 1 for key in written["keys"])
    shown = run_cli("retarget", "show", "--model", str(lerp_model))
    assert shown.returncode == 0, shown.stderr
    headers = [line.split(":")[0] for line in shown.stdout.splitlines() if not line[0].isspace()]
    assert headers == list(PRESET_NAMES)
    assert "52 controls" in shown.stdout and "15 controls" in shown.stdout


def test_a_malformed_pairs_file_exits_with_the_code_file_and_field(
    lerp_model: Path, tmp_path: Path
) -> None:
    pairs = tmp_path / "pairs.json"
    bad = json.loads(json.dumps(PAIRS))
    bad["keys"][1]["source"]["noSuchChannel"] = 1.0
    pairs.write_text(json.dumps(bad))
    result = run_cli(
        "retarget", "fit", "--model", str(lerp_model), "--pairs", str(pairs), "--name", "jaw"
    )
    assert result.returncode == 2
    assert result.stderr.strip().startswith(
        f"error [model_invalid]: {pairs}: keys[1].source.noSuchChannel:"
    )
    unknown = run_cli("retarget", "build", "--model", str(lerp_model), "--target", "rig9")
    assert unknown.returncode == 2
    assert unknown.stderr == (
        f"error [unknown_retarget]: target: no rig preset 'rig9'; the presets: "
        f"{', '.join(PRESET_NAMES)}\n"
    )


def test_show_with_a_name_shows_only_that_map_and_refuses_an_unknown_one(
    lerp_model: Path, tmp_path: Path
) -> None:
    fit_jaw(lerp_model, tmp_path)
    for name, controls in (("jaw", "open, shut"), ("oculus15", "viseme_sil")):
        shown = run_cli("retarget", "show", "--model", str(lerp_model), name)
        assert shown.returncode == 0, shown.stderr
        headers = [line for line in shown.stdout.splitlines() if not line[0].isspace()]
        assert [header.split(":")[0] for header in headers] == [name]
        assert f"  controls: {controls}" in shown.stdout
    unknown = run_cli("retarget", "show", "--model", str(lerp_model), "nope")
    assert unknown.returncode == 2
    assert unknown.stdout == ""
    assert unknown.stderr == (
        f"error [unknown_retarget]: {lerp_model}: the model has no retarget map 'nope'; "
        f"its maps: {', '.join(PRESET_NAMES)}, jaw\n"
    )


def test_show_without_a_model_lists_every_preset_and_its_controls() -> None:
    shown = run_cli("retarget", "show")
    assert shown.returncode == 0, shown.stderr
    headers = [line for line in shown.stdout.splitlines() if not line[0].isspace()]
    assert [header.split(":")[0] for header in headers] == list(PRESET_NAMES)
    assert (
        "  controls: aa, ih, ou, ee, oh, blink, happy, angry, sad, relaxed, surprised, neutral"
        in (shown.stdout)
    )
    assert "  controls: A, I, U, E, O, Blink, Joy, Angry, Sorrow, Fun, Neutral" in shown.stdout
    one = run_cli("retarget", "show", "metahuman")
    assert one.returncode == 0 and one.stdout.startswith("metahuman: ")
    assert "  controls: EyeBlinkLeft, " in one.stdout and ", JawOpen, " in one.stdout
    unknown = run_cli("retarget", "show", "vrm2")
    assert unknown.returncode == 2
    assert unknown.stderr == (
        f"error [unknown_retarget]: name: no rig preset 'vrm2'; the presets: "
        f"{', '.join(PRESET_NAMES)}\n"
    )
    refused = run_cli("retarget", "build", "--target", "vrm1")
    assert refused.returncode == 2 and "--model" in refused.stderr


def test_synth_through_the_vrm1_preset_closes_on_m_and_opens_in_aa_on_aa(
    trained_models: dict[str, Model], tmp_path: Path
) -> None:
    model = tmp_path / "dam"
    trained_models["dam"].save(model)
    data = synth_json(model, tmp_path, "--retarget", "vrm1")
    assert data["channels"][:6] == ["aa", "ih", "ou", "ee", "oh", "blink"]
    frames = np.array(data["frames"], dtype=np.float64)
    fps = float(data["fps"])
    mouth = frames[:, :5]
    # PHONES: M over 0.3-0.5 s, AA over 0.5-0.9 s.
    assert mouth[round(0.4 * fps)].max() <= 0.15
    assert mouth[round(0.7 * fps)].argmax() == 0 and mouth[round(0.7 * fps), 0] >= 0.8
