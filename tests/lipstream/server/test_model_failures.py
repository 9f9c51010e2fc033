"""A corrupt model next to a good one: ``lipstream serve`` on loopback serves the good one
and reports the bad one; it exits non-zero when nothing loads, or with --strict-models."""

from __future__ import annotations

import os
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import httpx
import numpy as np
import pytest

from lipstream.engines import engine_names
from lipstream.store import ARRAYS_NAME, load_arrays, save_model_dir
from tests.helpers import eventually, free_port, serve_command
from tests.live_server import READY_POLLS, stop_process
from tests.live_server import ready as is_ready

if TYPE_CHECKING:
    from lipstream.engines.base import Model

CORRUPT_VALUE = 2**30
CORRUPT_ARRAY = "all_index_transitions"


def _corrupt_anime_graph(model: Model, directory: Path) -> None:
    """The model with one int32 of the root's transitions set to 2**30 (the issue's case:
    the compiled search read it during start-up calibration and the process died)."""
    model.save(directory)
    arrays = {name: np.array(array) for name, array in load_arrays(directory).items()}
    assert arrays[CORRUPT_ARRAY].dtype == np.int32
    arrays[CORRUPT_ARRAY][0, 0] = CORRUPT_VALUE
    save_model_dir(directory, model.manifest, arrays)


@pytest.fixture(scope="module")
def mixed_dir(trained_models: dict[str, Model], tmp_path_factory: pytest.TempPathFactory) -> Path:
    directory = tmp_path_factory.mktemp("models-mixed")
    trained_models["viseme-lerp"].save(directory / "viseme-lerp")
    _corrupt_anime_graph(trained_models["anime-graph"], directory / "anime-graph")
    return directory


@pytest.fixture(scope="module")
def only_bad_dir(
    trained_models: dict[str, Model], tmp_path_factory: pytest.TempPathFactory
) -> Path:
    directory = tmp_path_factory.mktemp("models-bad")
    _corrupt_anime_graph(trained_models["anime-graph"], directory / "anime-graph")
    return directory


@pytest.fixture(scope="module")
def served(mixed_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Any]]:
    """``lipstream serve`` of the mixed directory, and the file its log goes to."""
    log_path = tmp_path_factory.mktemp("log") / "serve.log"
    port = free_port()
    base = f"http://127.0.0.1:{port}"
    with open(log_path, "w") as log:
        process = subprocess.Popen(
            serve_command(mixed_dir, port), stdout=log, stderr=subprocess.STDOUT
        )
        try:
            eventually(lambda: process.poll() is not None or is_ready(base), "ready", READY_POLLS)
            assert process.poll() is None, log_path.read_text()[-3000:]
            yield {"http": base, "log": log_path, "models": mixed_dir}
        finally:
            stop_process(process)


EXPECTED_FAILURE = {
    "model": "anime-graph",
    "engine": "anime-graph",
    "character": "demo",
    "code": "model_invalid",
    "where": f"anime-graph/{ARRAYS_NAME}: {CORRUPT_ARRAY}",
}


def test_the_good_model_serves_and_the_bad_one_is_reported(served: dict[str, Any]) -> None:
    base = served["http"]
    ready = httpx.get(f"{base}/readyz")
    assert ready.status_code == 200
    body = ready.json()
    assert body["ready"] is True
    (failure,) = body["failed_models"]
    message = failure.pop("message")
    assert failure == EXPECTED_FAILURE
    assert message.startswith(f"value {CORRUPT_VALUE} at (0, 0) is outside [-1, ")

    listing = httpx.get(f"{base}/v1/characters").json()
    assert listing["characters"] == [{"name": "demo", "engines": ["viseme-lerp"]}]
    assert [entry["model"] for entry in listing["failed_models"]] == ["anime-graph"]
    assert listing["failed_models"][0]["where"] == failure["where"]

    engines = {e["name"]: e["loaded"] for e in httpx.get(f"{base}/v1/engines").json()["engines"]}
    assert engines == {name: name == "viseme-lerp" for name in engine_names()}
    answer = httpx.post(
        f"{base}/v1/synthesize",
        json={
            "engine": "viseme-lerp",
            "character": "demo",
            "fps": 30,
            "items": [{"phoneme": "HH", "start": 0.0, "end": 0.1}],
        },
        timeout=30,
    )
    assert answer.status_code == 200, answer.text

    log = served["log"].read_text()
    arrays = served["models"] / "anime-graph" / ARRAYS_NAME
    assert (
        f"model {served['models'] / 'anime-graph'} is not served: {arrays}: {CORRUPT_ARRAY}" in log
    )


def _run_serve(models: Path, *extra: str, env: dict[str, str] | None = None) -> Any:
    return subprocess.run(
        serve_command(models, free_port(), *extra),
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
        env={**os.environ, **(env or {})},
    )


def _one_line_error(stderr: str, models: Path) -> str:
    lines = [line for line in stderr.splitlines() if line.startswith("error [")]
    assert len(lines) == 1, stderr
    arrays = models / "anime-graph" / ARRAYS_NAME
    assert lines[0].startswith("error [model_invalid]: "), lines[0]
    return lines[0].replace(str(arrays), "ARRAYS")


def test_serve_exits_non_zero_when_no_model_loads(only_bad_dir: Path) -> None:
    result = _run_serve(only_bad_dir)
    assert result.returncode == 2
    line = _one_line_error(result.stderr, only_bad_dir)
    assert line.startswith(f"error [model_invalid]: {only_bad_dir}: no model could be loaded (")
    assert f"ARRAYS: {CORRUPT_ARRAY}: value {CORRUPT_VALUE}" in line


@pytest.mark.parametrize("how", ["flag", "environment"])
def test_strict_models_refuses_to_start_with_any_bad_model(mixed_dir: Path, how: str) -> None:
    if how == "flag":
        result = _run_serve(mixed_dir, "--strict-models")
    else:
        result = _run_serve(mixed_dir, env={"LIPSTREAM_STRICT_MODELS": "1"})
    assert result.returncode == 2
    line = _one_line_error(result.stderr, mixed_dir)
    assert line.startswith(f"error [model_invalid]: ARRAYS: {CORRUPT_ARRAY}: value {CORRUPT_VALUE}")
