"""The trained expressive-dp model: hard constraints, emotion modifiers, contamination, the
full search against fixed lags, and coded errors for bad constraints."""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from lipstream.corpus import Corpus
from lipstream.engines import load_model
from lipstream.engines.base import Model
from lipstream.engines.expressive_dp import ExpressiveDpModel
from lipstream.engines.expressive_dp.search import NO_NODE
from lipstream.engines.expressive_dp.synthesizer import PathSynthesizer
from lipstream.errors import InvalidRequestError, ModelStoreError
from lipstream.phonemes import PHONEME_INDEX, SILENCE
from lipstream.store import read_manifest, save_model_dir
from lipstream.timeline import EMOTIONS, PhonemeSpan


@pytest.fixture(scope="module")
def model(trained_models: dict[str, Model]) -> ExpressiveDpModel:
    found = trained_models["expressive-dp"]
    assert isinstance(found, ExpressiveDpModel)
    return found


@pytest.fixture(scope="module")
def spans(small_demo_corpus: Corpus) -> list[PhonemeSpan]:
    return small_demo_corpus.split()[1].utterances[0].phones


def _path(model: ExpressiveDpModel, spans: list[PhonemeSpan], **options: Any) -> list[int]:
    synthesizer = model.start(fps=60, **options)
    synthesizer.feed(spans)
    synthesizer.finish()
    return [int(node) for node in str(synthesizer.stats["nodes"]).split()]


def _cost(model: ExpressiveDpModel, spans: list[PhonemeSpan], **options: Any) -> float:
    synthesizer = model.start(fps=60, **options)
    synthesizer.feed(spans)
    synthesizer.finish()
    return float(synthesizer.stats["path_cost"])


def test_hard_constraints_are_satisfied_on_every_rung(
    model: ExpressiveDpModel, spans: list[PhonemeSpan]
) -> None:
    speech = [i for i, span in enumerate(spans) if span.phoneme != SILENCE]
    first, second = speech[2], speech[5]
    # nodes of another phoneme and another emotion than the spans: only B can place them
    other = np.flatnonzero(
        (model.nodes.phoneme != PHONEME_INDEX[spans[first].phoneme])
        & (model.nodes.emotion != EMOTIONS.index("neutral"))
    )
    chosen = {first: int(other[0]), second: int(other[-1])}
    for options in ({}, {"lag": 0}, {"lag": "full"}, {"causal": True}):
        path = _path(
            model,
            spans,
            emotion="neutral",
            constraints={str(k): v for k, v in chosen.items()},
            **options,
        )
        assert path[first] == chosen[first] and path[second] == chosen[second], options
        unconstrained = _path(model, spans, emotion="neutral", **options)
        assert unconstrained[first] != chosen[first]


def test_the_full_search_is_never_worse_than_a_fixed_lag(
    model: ExpressiveDpModel, spans: list[PhonemeSpan]
) -> None:
    full = _cost(model, spans, lag="full")
    for lag in (0, 1, 2, 4):
        assert full <= _cost(model, spans, lag=lag) + 1e-9
    assert _cost(model, spans, lag=64) == pytest.approx(full, rel=1e-12)


def test_emotion_modifiers_move_the_nodes_toward_the_emotion(
    model: ExpressiveDpModel, spans: list[PhonemeSpan]
) -> None:
    def share(path: list[int], emotion: str, rows: range) -> float:
        nodes = [path[i] for i in rows if path[i] != NO_NODE]
        return float(np.mean(model.nodes.emotion[nodes] == EMOTIONS.index(emotion)))

    everything = range(len(spans))
    neutral = _path(model, spans, emotion="neutral")
    for emotion in ("happy", "angry", "sad"):
        assert share(_path(model, spans, emotion=emotion), emotion, everything) > share(
            neutral, emotion, everything
        )
    # per-span modifiers: the second half angry, the first half neutral
    half = len(spans) // 2
    mixed = [
        PhonemeSpan(s.phoneme, s.start, s.end, "angry" if i >= half else None)
        for i, s in enumerate(spans)
    ]
    path = _path(model, mixed, emotion="neutral")
    assert share(path, "angry", range(half, len(spans))) > share(path, "angry", range(half))


def test_bad_constraints_are_coded_errors_naming_them(
    model: ExpressiveDpModel, spans: list[PhonemeSpan]
) -> None:
    size = model.nodes.size
    with pytest.raises(InvalidRequestError) as caught:
        model.start(fps=60, constraints={"3": size})
    assert caught.value.where == "options.constraints.3" and f"node {size}" in caught.value.message
    with pytest.raises(InvalidRequestError) as caught:
        model.start(fps=60, constraints=[[-1, 0]])
    assert caught.value.where == "options.constraints.0"
    synthesizer = model.start(fps=60, constraints={"999": 0})
    synthesizer.feed(spans)
    with pytest.raises(InvalidRequestError) as caught:
        synthesizer.finish()
    assert caught.value.where == "options.constraints.999"
    assert f"only {len(spans)} phonemes" in caught.value.message


def test_a_constraint_on_a_silence_is_a_coded_error_naming_it(
    model: ExpressiveDpModel, spans: list[PhonemeSpan]
) -> None:
    pause = next(i for i, span in enumerate(spans) if span.phoneme == SILENCE)
    synthesizer = model.start(fps=60, constraints={str(pause): 0})
    with pytest.raises(InvalidRequestError) as caught:
        synthesizer.feed(spans)
    assert caught.value.where == f"options.constraints.{pause}"
    assert "silence" in caught.value.message


def test_a_silence_has_no_node_and_commits_every_node_before_it(
    model: ExpressiveDpModel, spans: list[PhonemeSpan]
) -> None:
    pause = next(i for i, span in enumerate(spans) if i > 2 and span.phoneme == SILENCE)
    full = _path(model, spans, lag="full")
    assert [full[i] == NO_NODE for i in range(len(spans))] == [
        span.phoneme == SILENCE for span in spans
    ]
    # at a lag longer than the input, the nodes before the pause are committed once it
    # arrives, before finish, and they are the full search's
    synthesizer = model.start(fps=60, lag=64)
    synthesizer.feed(spans[: pause + 1])
    assert isinstance(synthesizer, PathSynthesizer)
    synthesizer.commit()
    assert synthesizer.path == full[: pause + 1]
    synthesizer.feed(spans[pause + 1 : pause + 3])
    synthesizer.commit()
    assert len(synthesizer.path) == pause + 1  # the next segment waits for its lag


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_contamination_is_persisted_beside_the_model_honoured_and_reversible(
    model: ExpressiveDpModel, spans: list[PhonemeSpan], tmp_path: Path
) -> None:
    model.save(tmp_path / "m")
    arrays = _digest(tmp_path / "m" / "arrays.npz")
    first = load_model(tmp_path / "m")
    assert isinstance(first, ExpressiveDpModel)
    before = _path(first, spans)
    marked = sorted(set(before) - {NO_NODE})
    assert first.contamination.change(marked, []) == marked
    assert (tmp_path / "m" / "contamination.json").is_file()
    # another process's copy of the model (here: another load) sees the change
    second = load_model(tmp_path / "m")
    assert isinstance(second, ExpressiveDpModel)
    after = _path(second, spans)
    assert not set(after) & set(marked)
    with pytest.raises(InvalidRequestError, match="contaminated"):
        second.start(fps=60, constraints={"1": marked[0]})
    assert first.contamination.change([], marked) == []
    assert _path(second, spans) == before
    assert _digest(tmp_path / "m" / "arrays.npz") == arrays


@pytest.mark.parametrize(
    ("name", "damage"),
    [
        ("node_pre", lambda a: np.full_like(a, 10**6)),
        ("node_suc", lambda a: np.roll(a, 1)),
        ("alphas", lambda a: np.array([1.0, 1.0, 1.0, 1.5, 1.0, 1.0])),
        ("map_points", lambda a: a[:-1]),
    ],
)
def test_a_damaged_array_is_refused_at_load_naming_it(
    model: ExpressiveDpModel, tmp_path: Path, name: str, damage: Any
) -> None:
    model.save(tmp_path / "m")
    arrays = dict(np.load(tmp_path / "m" / "arrays.npz"))
    arrays[name] = damage(arrays[name])
    save_model_dir(tmp_path / "m", read_manifest(tmp_path / "m"), arrays)
    with pytest.raises(ModelStoreError) as caught:
        load_model(tmp_path / "m")
    assert caught.value.code == "model_invalid" and name in str(caught.value)
