"""``lipstream serve`` without ``--models`` rebuilds a cached demo character that cannot serve
every registered engine (one missing, or one that no longer loads) or word timings (a model
without its duration model)."""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import TYPE_CHECKING

from lipstream.cli.demo_cache import _stale_demo
from lipstream.engines import engine_names
from lipstream.frontends.word_durations import MANIFEST_FILE

if TYPE_CHECKING:
    from lipstream.engines.base import Model
    from lipstream.frontends.word_durations import WordDurationModel


def _save(
    models: dict[str, Model], durations: WordDurationModel, directory: Path, names: list[str]
) -> None:
    for name in names:
        models[name].save(directory / name)
        durations.save(directory / name)


def test_a_demo_with_every_engine_is_kept(
    trained_models: dict[str, Model], word_durations: WordDurationModel, tmp_path: Path
) -> None:
    _save(trained_models, word_durations, tmp_path, engine_names())
    assert not _stale_demo(tmp_path)


def test_a_demo_built_before_word_timings_is_rebuilt(
    trained_models: dict[str, Model], word_durations: WordDurationModel, tmp_path: Path
) -> None:
    _save(trained_models, word_durations, tmp_path, engine_names())
    (tmp_path / "dam" / MANIFEST_FILE).unlink()
    assert _stale_demo(tmp_path)


def test_a_demo_missing_an_engine_is_rebuilt(
    trained_models: dict[str, Model], word_durations: WordDurationModel, tmp_path: Path
) -> None:
    _save(trained_models, word_durations, tmp_path, engine_names()[:-1])
    assert _stale_demo(tmp_path)


def test_a_demo_whose_model_no_longer_loads_is_rebuilt(
    trained_models: dict[str, Model], word_durations: WordDurationModel, tmp_path: Path
) -> None:
    _save(trained_models, word_durations, tmp_path, engine_names())
    (tmp_path / "viseme-lerp" / "arrays.npz").write_bytes(b"not an archive")
    assert _stale_demo(tmp_path)
    shutil.rmtree(tmp_path / "viseme-lerp")
    for name in engine_names()[1:]:
        shutil.rmtree(tmp_path / name)
    (tmp_path / "stray").mkdir()
    assert _stale_demo(tmp_path)  # no model at all
