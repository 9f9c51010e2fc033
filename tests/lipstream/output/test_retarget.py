"""Rig cross-mapping: bounds, key-pose reproduction, a known linear rig recovered, NNLS against
brute force, the shipped targets, and coded errors for malformed files."""

from __future__ import annotations

import itertools
import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pytest

from lipstream.corpus.livelink import ARKIT_BLENDSHAPES
from lipstream.errors import ModelStoreError
from lipstream.output.retarget import (
    KeyPosePairs,
    fit_controls,
    fit_map,
    load_map,
    read_pairs,
    save_map,
)
from lipstream.output.rig_presets import model_maps
from lipstream_client.channels import OCULUS15_VISEMES

if TYPE_CHECKING:
    from lipstream.engines.base import Model

CHANNELS = ("jawOpen", "mouthClose", "mouthFunnel", "mouthPucker", "mouthSmileLeft", "eyeBlinkLeft")
CONTROLS = ("open", "close", "round", "smile", "blink")


def generated_rig(seed: int = 3) -> tuple[KeyPosePairs, np.ndarray]:
    """Four independent key poses and a known non-negative linear rig map G with G s_k in
    [0, 1]: the pairs are (s_k, G s_k)."""
    generator = np.random.default_rng(seed)
    keys = generator.uniform(0.0, 1.0, (4, len(CHANNELS)))
    rig = generator.uniform(0.0, 1.0, (len(CONTROLS), len(CHANNELS)))
    rig /= (rig @ keys.T).max() * 1.25
    pairs = KeyPosePairs(
        channels=CHANNELS,
        controls=CONTROLS,
        key_names=("A", "B", "C", "D"),
        source_rest=np.zeros(len(CHANNELS)),
        control_rest=np.zeros(len(CONTROLS)),
        source_keys=keys,
        control_keys=keys @ rig.T,
        channel_weights=np.ones(len(CHANNELS)),
    )
    return pairs, rig


def test_a_known_linear_rig_is_recovered_on_blends_of_the_key_poses() -> None:
    pairs, rig = generated_rig()
    retarget = fit_map("gen", pairs)
    blends = np.random.default_rng(5).dirichlet(np.ones(4), 50) * 0.9
    frames = blends @ pairs.source_keys
    np.testing.assert_allclose(retarget.apply(frames), frames @ rig.T, atol=1e-9)
    np.testing.assert_allclose(retarget.blend_weights(frames), blends, atol=1e-9)


def test_each_key_pose_maps_to_its_controls() -> None:
    pairs, _ = generated_rig()
    retarget = fit_map("gen", pairs)
    np.testing.assert_allclose(retarget.apply(pairs.source_keys), pairs.control_keys, atol=1e-9)
    assert max(retarget.reproduction_error().values()) < 1e-9


def test_controls_stay_in_the_unit_interval_for_any_frame() -> None:
    pairs, _ = generated_rig()
    retarget = fit_map("gen", pairs)
    frames = np.random.default_rng(8).normal(0.0, 10.0, (200, len(CHANNELS)))
    controls = retarget.apply(frames)
    assert controls.min() >= 0.0 and controls.max() <= 1.0
    assert controls.max() == 1.0  # large frames do drive controls to the bound


def test_a_non_finite_frame_stays_non_finite_for_the_caller_to_report() -> None:
    pairs, _ = generated_rig()
    frames = np.full((2, len(CHANNELS)), -0.5)
    frames[0, 2] = np.nan
    controls = fit_map("gen", pairs).apply(frames)
    assert np.isnan(controls[0]).all() and np.isfinite(controls[1]).all()


def brute_force_nnls(system: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The best non-negative solution over every support set, by plain least squares."""
    best, best_error = np.zeros(system.shape[1]), float(np.sum(target**2))
    for size in range(1, system.shape[1] + 1):
        for support in itertools.combinations(range(system.shape[1]), size):
            solution, *_ = np.linalg.lstsq(system[:, support], target, rcond=None)
            if (solution < 0).any():
                continue
            candidate = np.zeros(system.shape[1])
            candidate[list(support)] = solution
            error = float(np.sum((system @ candidate - target) ** 2))
            if error < best_error - 1e-12:
                best, best_error = candidate, error
    return best


def test_blend_weights_are_the_nonnegative_least_squares_optimum() -> None:
    pairs, _ = generated_rig()
    weights = np.array([1.0, 2.0, 1.0, 0.5, 1.0, 0.0])
    pairs = KeyPosePairs(**{**pairs.__dict__, "channel_weights": weights})
    retarget = fit_map("gen", pairs)
    generator = np.random.default_rng(2)
    inside = generator.uniform(0.1, 1.0, (6, 4)) @ pairs.source_keys
    frames = np.vstack([inside, generator.normal(0.3, 0.5, (12, len(CHANNELS)))])
    system = pairs.source_keys.T * weights[:, None]
    free = np.linalg.lstsq(system, (frames * weights).T, rcond=None)[0].T
    negative = (free < 0).any(axis=1)
    assert negative.any() and not negative.all()  # both the direct and the NNLS path
    for frame, found in zip(frames, retarget.blend_weights(frames)):
        np.testing.assert_allclose(found, brute_force_nnls(system, frame * weights), atol=1e-8)


def test_fit_controls_recovers_known_controls_and_respects_bounds() -> None:
    generator = np.random.default_rng(4)
    rest = generator.uniform(0.0, 0.2, 8)
    shapes = rest + generator.uniform(0.0, 1.0, (5, 8))
    known = np.array([0.0, 0.3, 1.0, 0.7, 0.1])
    pose = rest + known @ (shapes - rest)
    np.testing.assert_allclose(fit_controls(shapes, rest, pose), known, atol=1e-8)
    beyond = fit_controls(shapes, rest, rest + 5.0 * (shapes[0] - rest))
    assert beyond.min() >= 0.0 and beyond.max() <= 1.0
    assert beyond[0] == pytest.approx(1.0)


def test_arkit52_passes_shared_channels_and_holds_the_rest_at_zero(
    trained_models: dict[str, Model],
) -> None:
    model = trained_models["viseme-lerp"]
    retarget = model_maps(model, None, only="arkit52")["arkit52"]
    assert retarget.controls == ARKIT_BLENDSHAPES
    frames = np.random.default_rng(1).uniform(-0.2, 1.2, (30, len(model.channels)))
    expected = np.zeros((30, len(ARKIT_BLENDSHAPES)))
    for column, name in enumerate(model.channels):
        if name in ARKIT_BLENDSHAPES:
            expected[:, ARKIT_BLENDSHAPES.index(name)] = np.clip(frames[:, column], 0.0, 1.0)
    np.testing.assert_allclose(retarget.apply(frames), expected, atol=1e-12)


def test_oculus15_maps_silence_to_sil_and_keeps_controls_in_bounds(
    trained_models: dict[str, Model],
) -> None:
    from lipstream.output.probes import probe_key_poses

    model = trained_models["viseme-lerp"]
    retarget = model_maps(model, None, only="oculus15")["oculus15"]
    assert retarget.controls == OCULUS15_VISEMES
    poses = probe_key_poses(model)
    controls = retarget.apply(poses)
    assert controls.min() >= 0.0 and controls.max() <= 1.0
    np.testing.assert_allclose(controls[0], np.eye(15)[0], atol=1e-9)
    reproduced = retarget.reproduction_error()
    assert set(OCULUS15_VISEMES[1:]) <= set(reproduced)


def test_a_map_round_trips_through_its_files(tmp_path: Path) -> None:
    pairs, _ = generated_rig()
    directory = save_map(tmp_path / "rig", fit_map("rig", pairs))
    loaded = load_map(directory, CHANNELS)
    assert (loaded.name, loaded.controls, loaded.pairs.key_names) == (
        "rig",
        CONTROLS,
        pairs.key_names,
    )
    frames = np.random.default_rng(0).uniform(0.0, 1.0, (5, len(CHANNELS)))
    np.testing.assert_array_equal(loaded.apply(frames), fit_map("rig", pairs).apply(frames))
    manifest = json.loads((directory / "retarget.json").read_text())
    assert max(manifest["reproduction_error"].values()) < 1e-9


def edited_manifest(tmp_path: Path, **changes: Any) -> Path:
    pairs, _ = generated_rig()
    directory = save_map(tmp_path / "rig", fit_map("rig", pairs))
    manifest = json.loads((directory / "retarget.json").read_text())
    manifest.update(changes)
    (directory / "retarget.json").write_text(json.dumps(manifest))
    return directory


@pytest.mark.parametrize(
    ("changes", "field"),
    [
        ({"channels": list(reversed(CHANNELS))}, "channels"),
        ({"controls": ["open", "open", "a", "b", "c"]}, "controls"),
        ({"schema_version": 9}, "schema_version"),
        ({"keys": "A"}, "keys"),
        ({"name": 3}, "name"),
    ],
)
def test_a_malformed_manifest_is_model_invalid_naming_file_and_field(
    tmp_path: Path, changes: dict[str, Any], field: str
) -> None:
    directory = edited_manifest(tmp_path, **changes)
    with pytest.raises(ModelStoreError) as caught:
        load_map(directory, CHANNELS)
    assert caught.value.code == "model_invalid"
    assert caught.value.where == f"{directory / 'retarget.json'}: {field}"


@pytest.mark.parametrize(
    ("array", "value", "message"),
    [
        ("control_keys", np.full((4, 5), 1.5), "[0, 1]"),
        ("source_keys", np.full((3, 6), 0.5), "shape"),
        ("source_rest", np.full(6, np.nan), "NaN"),
        ("channel_weights", np.zeros(6), "at least one"),
    ],
)
def test_malformed_arrays_are_model_invalid_naming_the_array(
    tmp_path: Path, array: str, value: np.ndarray, message: str
) -> None:
    pairs, _ = generated_rig()
    directory = save_map(tmp_path / "rig", fit_map("rig", pairs))
    with np.load(directory / "arrays.npz") as stored:
        arrays = dict(stored)
    arrays[array] = value
    np.savez(directory / "arrays.npz", **arrays)
    with pytest.raises(ModelStoreError) as caught:
        load_map(directory, CHANNELS)
    assert caught.value.where == f"{directory / 'arrays.npz'}: {array}"
    assert message.lower() in caught.value.message.lower()


def pairs_file(tmp_path: Path, data: object) -> Path:
    path = tmp_path / "pairs.json"
    path.write_text(json.dumps(data))
    return path


VALID_PAIRS: dict[str, Any] = {
    "controls": ["open", "close"],
    "rest": {"source": {"mouthClose": 0.1}, "controls": {"close": 0.0}},
    "keys": [
        {"name": "AA", "source": {"jawOpen": 0.8}, "controls": {"open": 1.0}},
        {"name": "MM", "source": {"mouthClose": 0.9}, "controls": {"close": 1.0}},
    ],
    "channel_weights": {"eyeBlinkLeft": 0},
}


def test_a_pairs_file_gives_the_poses_with_unnamed_values_at_rest(tmp_path: Path) -> None:
    pairs = read_pairs(pairs_file(tmp_path, VALID_PAIRS), CHANNELS)
    assert pairs.key_names == ("AA", "MM")
    np.testing.assert_array_equal(pairs.source_keys[0], [0.8, 0.1, 0, 0, 0, 0])
    np.testing.assert_array_equal(pairs.source_keys[1], [0.0, 0.9, 0, 0, 0, 0])
    np.testing.assert_array_equal(pairs.control_keys, [[1.0, 0.0], [0.0, 1.0]])
    np.testing.assert_array_equal(pairs.channel_weights, [1, 1, 1, 1, 1, 0])
    retarget = fit_map("pairs", pairs)
    np.testing.assert_allclose(
        retarget.apply(np.array([[0.4, 0.1, 0, 0, 0, 1.0]])), [[0.5, 0.0]], atol=1e-12
    )


@pytest.mark.parametrize(
    ("edit", "field"),
    [
        (lambda d: d["keys"][1]["source"].update(tongueOut=1.0), "keys[1].source.tongueOut"),
        (lambda d: d["keys"][0]["controls"].update(open=1.5), "control_keys"),
        (lambda d: d["keys"][0].pop("controls"), "keys[0].controls"),
        (lambda d: d["keys"][0]["source"].update(jawOpen="wide"), "keys[0].source.jawOpen"),
        (lambda d: d.pop("controls"), "controls"),
        (lambda d: d.update(keys=[]), "keys"),
        (lambda d: d["rest"]["controls"].update(shut=0.0), "rest.controls.shut"),
    ],
)
def test_a_malformed_pairs_file_is_model_invalid_naming_file_and_field(
    tmp_path: Path, edit: Any, field: str
) -> None:
    data = json.loads(json.dumps(VALID_PAIRS))
    edit(data)
    path = pairs_file(tmp_path, data)
    with pytest.raises(ModelStoreError) as caught:
        read_pairs(path, CHANNELS)
    assert caught.value.code == "model_invalid"
    assert caught.value.where == f"{path}: {field}"


def test_a_pairs_file_that_is_not_json_names_the_file(tmp_path: Path) -> None:
    path = tmp_path / "pairs.json"
    path.write_text("{not json")
    with pytest.raises(ModelStoreError) as caught:
        read_pairs(path, CHANNELS)
    assert caught.value.where == str(path)
