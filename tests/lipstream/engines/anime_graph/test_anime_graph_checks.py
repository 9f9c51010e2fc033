"""A stored anime-graph model is checked at load: corrupted copies of a real trained model
are refused as ``model_invalid`` naming the file and the array or field, and no corrupted
copy, loaded and served in a subprocess, kills the process by a signal."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from lipstream.engines.anime_graph.checks import check_stored_model
from lipstream.errors import ModelStoreError
from lipstream.store import ARRAYS_NAME, MANIFEST_NAME, ModelManifest
from tests.helpers import REPO
from tests.lipstream.engines.anime_graph.model_corruption import (
    CORRUPTIONS,
    INDEX_ARRAYS,
    Corruption,
    read_sweep,
    resolve,
)

if TYPE_CHECKING:
    from lipstream.engines.base import Model

RANDOM_VARIANTS = 20
SWEEP_TIMEOUT_S = 900


@pytest.fixture(scope="module")
def stored(trained_models: dict[str, Model], tmp_path_factory: pytest.TempPathFactory) -> Path:
    directory = tmp_path_factory.mktemp("anime-graph-stored") / "anime-graph"
    trained_models["anime-graph"].save(directory)
    return directory


@pytest.fixture(scope="module")
def sweep(stored: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """Every corrupted variant (and ``RANDOM_VARIANTS`` in-range ones), loaded and served in
    one subprocess."""
    scratch = tmp_path_factory.mktemp("anime-graph-corrupt")
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "tests.lipstream.engines.anime_graph.model_corruption",
            str(stored),
            str(scratch),
            str(RANDOM_VARIANTS),
        ],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=SWEEP_TIMEOUT_S,
        check=False,
    )
    outcomes, unfinished = read_sweep(result.stdout)
    return {
        "returncode": result.returncode,
        "stderr": result.stderr,
        "outcomes": outcomes,
        "unfinished": unfinished,
        "scratch": scratch,
        "manifest": json.loads((stored / MANIFEST_NAME).read_text()),
    }


@pytest.mark.slow
def test_no_corrupted_model_kills_the_process(sweep: dict[str, Any]) -> None:
    code = sweep["returncode"]
    if code < 0:
        pytest.fail(
            f"the sweep died by {signal.Signals(-code).name} while loading or serving "
            f"variant {sweep['unfinished']!r}"
        )
    assert code == 0, sweep["stderr"][-3000:]
    outcomes = sweep["outcomes"]
    assert {corruption.id for corruption in CORRUPTIONS} <= set(outcomes)
    assert len(outcomes) == len(CORRUPTIONS) + RANDOM_VARIANTS
    for variant, outcome in outcomes.items():
        # Refused, or served: every request gives finite frames or a request error.
        assert "raised" not in outcome, (variant, outcome)
        if "loaded" in outcome:
            assert not any(
                result == "not finite" or result.startswith("raised")
                for result in outcome["loaded"].values()
            ), (variant, outcome)
        else:
            assert outcome["code"] == "model_invalid", (variant, outcome)


@pytest.mark.slow
@pytest.mark.parametrize("corruption", CORRUPTIONS, ids=[c.id for c in CORRUPTIONS])
def test_corruption_is_refused_naming_file_and_array(
    corruption: Corruption, sweep: dict[str, Any]
) -> None:
    outcome = sweep["outcomes"].get(corruption.id)
    assert outcome is not None, f"the sweep stopped before {corruption.id}"
    assert outcome.get("code") == "model_invalid", outcome
    where = outcome["where"]
    path, _, named = where.partition(": ")
    assert path == str(sweep["scratch"] / "model" / corruption.file), where
    names = [resolve(name, sweep["manifest"]) for name in corruption.names]
    named = named or corruption.file
    assert any(named == name or named.startswith(f"{name}[") for name in names), (
        named,
        names,
        outcome["message"],
    )


@pytest.fixture(scope="module")
def pristine(stored: Path) -> tuple[ModelManifest, dict[str, np.ndarray]]:
    from lipstream.store import load_arrays, read_manifest

    return read_manifest(stored), {k: np.array(v) for k, v in load_arrays(stored).items()}


def test_the_trained_model_passes(
    pristine: tuple[ModelManifest, dict[str, np.ndarray]], stored: Path
) -> None:
    manifest, arrays = pristine
    check_stored_model(manifest, arrays, stored)


@settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    pick=st.integers(0, len(INDEX_ARRAYS) - 1),
    spot=st.floats(0.0, 1.0, exclude_max=True),
    outside=st.one_of(st.integers(-(2**31), -2), st.integers(2**20, 2**31 - 1)),
)
def test_any_index_out_of_range_is_refused_naming_its_array(
    pristine: tuple[ModelManifest, dict[str, np.ndarray]],
    stored: Path,
    pick: int,
    spot: float,
    outside: int,
) -> None:
    """Only the checks run here (plain numpy), so a miss fails the test, not the process.
    No stored index is below -1 or anywhere near 2**20 in the small demo model."""
    manifest, arrays = pristine
    name = resolve(INDEX_ARRAYS[pick], json.loads((stored / MANIFEST_NAME).read_text()))
    changed = dict(arrays)
    array = arrays[name].astype(np.int64)
    if array.size == 0:
        return
    array.reshape(-1)[int(spot * array.size)] = outside
    changed[name] = array
    with pytest.raises(ModelStoreError) as caught:
        check_stored_model(manifest, changed, stored)
    assert caught.value.code == "model_invalid"
    assert caught.value.where == f"{stored / ARRAYS_NAME}: {name}"
