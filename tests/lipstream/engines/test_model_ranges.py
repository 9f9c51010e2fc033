"""Issue 29, defect 7: finite but absurd stored values are refused at load, naming the array.

Every engine's model is trained on the small demo corpus and saved; each variant changes
one stored float array and must be refused with ``model_invalid`` at
``<model>/arrays.npz: <array>``. The variants: each float array's first value made
absurdly large or small in its dtype (the issue's ``kappa[0] = 1e300``), and, per engine,
values inside ``MAX_MAGNITUDE`` but outside the range that array documents. The
unchanged models still load.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pytest

from lipstream.engines import engine_names, load_model
from lipstream.errors import ModelStoreError
from lipstream.store import ARRAYS_NAME, load_arrays, read_manifest, save_model_dir

if TYPE_CHECKING:
    from lipstream.engines.base import Model


@pytest.fixture(scope="module")
def saved(
    trained_models: dict[str, Model], tmp_path_factory: pytest.TempPathFactory
) -> dict[str, Path]:
    directory = tmp_path_factory.mktemp("models-ranges")
    for name, model in trained_models.items():
        model.save(directory / name)
    return {name: directory / name for name in trained_models}


def _variant(source: Path, target: Path, name: str, change: Callable[[np.ndarray], object]) -> None:
    """``source``'s model with array ``name`` changed by ``change(array)`` (in place)."""
    arrays = {key: np.array(value) for key, value in load_arrays(source).items()}
    change(arrays[name])
    save_model_dir(target, read_manifest(source), arrays)


def _refusal(directory: Path) -> ModelStoreError:
    with pytest.raises(ModelStoreError) as caught:
        load_model(directory)
    return caught.value


def _float_arrays(directory: Path) -> list[str]:
    return sorted(
        name
        for name, array in load_arrays(directory).items()
        if array.dtype.kind == "f" and array.size > 0
    )


@pytest.mark.parametrize("engine", engine_names())
def test_the_trained_models_load(saved: dict[str, Path], engine: str) -> None:
    assert load_model(saved[engine]).manifest.engine == engine


@pytest.mark.parametrize("engine", engine_names())
def test_an_absurd_value_in_any_float_array_is_refused_naming_it(
    saved: dict[str, Path], engine: str, tmp_path: Path
) -> None:
    names = _float_arrays(saved[engine])
    assert len(names) >= 4
    for name in names:
        for sign in (1.0, -1.0):
            absurd = sign * 1e-4 * float(np.finfo(load_arrays(saved[engine])[name].dtype).max)

            def change(array: np.ndarray, value: float = absurd) -> None:
                array.flat[0] = value

            target = tmp_path / f"{name}{sign:+g}"
            _variant(saved[engine], target, name, change)
            error = _refusal(target)
            assert (error.code, error.where) == ("model_invalid", f"{target / ARRAYS_NAME}: {name}")


# (engine, array, value set at index 0, words of the refusal): inside MAX_MAGNITUDE, outside
# the range the array documents.
OUT_OF_RANGE = [
    ("viseme-lerp", "kappa", 1e-6, "outside [0.1, 100]"),
    ("viseme-lerp", "kappa", 1e3, "outside [0.1, 100]"),
    ("viseme-lerp", "duration_log_mean", 30.0, "outside [-6.90776, 4.09434]"),
    ("dam", "causal_kappa", 1e5, "outside [0.1, 100]"),
    ("dam", "duration_log_std", 50.0, "outside [0, 5]"),
    ("dam", "sigma", 1e4, "must lie in"),
    ("dam", "count_emotion", 2**40, "outside [0, 2147483648)"),
    ("cohen-massaro", "causal_kappa", 1e-9, "outside [0.1, 100]"),
    ("cohen-massaro", "duration_log_mean", -40.0, "outside [-6.90776, 4.09434]"),
    ("expressive-dp", "alphas", 50.0, "alpha1 is 50, outside the [0.01, 10]"),
    ("expressive-dp", "causal_kappa", 500.0, "outside [0.1, 100]"),
    ("anime-graph", "cutoffs", 1e5, "outside [0, 60]"),
]


@pytest.mark.parametrize(("engine", "name", "value", "words"), OUT_OF_RANGE)
def test_a_value_outside_its_documented_range_is_refused(
    saved: dict[str, Path], tmp_path: Path, engine: str, name: str, value: float, words: str
) -> None:
    def change(array: np.ndarray) -> None:
        array.flat[0] = value

    _variant(saved[engine], tmp_path / engine, name, change)
    error = _refusal(tmp_path / engine)
    assert (error.code, error.where) == (
        "model_invalid",
        f"{tmp_path / engine / ARRAYS_NAME}: {name}",
    )
    assert words in error.message


def test_the_issues_reordered_alphas_are_refused(saved: dict[str, Path], tmp_path: Path) -> None:
    def reorder(alphas: np.ndarray) -> None:
        alphas[:] = alphas[[5, 4, 2, 3, 1, 0]]

    _variant(saved["expressive-dp"], tmp_path / "edp", "alphas", reorder)
    error = _refusal(tmp_path / "edp")
    assert error.where == f"{tmp_path / 'edp' / ARRAYS_NAME}: alphas"
    assert error.message.startswith("alpha1 is 50, outside the [0.01, 10]")
