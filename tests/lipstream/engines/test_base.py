"""The engine conventions: hyperparameters are the constructor's signature, an engine holds
nothing else, and fitting leaves it unchanged."""

from __future__ import annotations

import copy
from typing import Any

import pytest

from lipstream.engines import engine_names, get_engine_class
from lipstream.engines.anime_graph import AnimeGraphEngine
from lipstream.engines.base import Engine, Model, SpanSynthesizer
from lipstream.errors import InvalidRequestError
from lipstream.timeline import PhonemeSpan
from tests.lipstream.engines.anime_graph.anime_synthetic import make_corpus


class _Toy(Engine):
    name = "toy"

    def __init__(self, alpha: float = 1.0, label: str = "x") -> None:
        self.alpha = alpha
        self.label = label
        self.scaled = 2.0 * alpha  # derived, not a hyperparameter
        self.notes: dict[str, int] = {}

    def fit(self, corpus: Any, *, progress: bool = False) -> Model:
        raise NotImplementedError


class _Loose(Engine):
    name = "loose"

    def __init__(self, **options: Any) -> None:
        self.options = options

    def fit(self, corpus: Any, *, progress: bool = False) -> Model:
        raise NotImplementedError


class _Bare(Engine):
    name = "bare"

    def fit(self, corpus: Any, *, progress: bool = False) -> Model:
        raise NotImplementedError


def test_hyperparameters_are_the_constructor_arguments_only() -> None:
    assert _Toy(alpha=0.5, label="y").hyperparameters() == {"alpha": 0.5, "label": "y"}
    assert _Toy.hyperparameter_names() == ["alpha", "label"]
    assert _Bare().hyperparameters() == {}


def test_an_engine_taking_keyword_arguments_is_refused() -> None:
    with pytest.raises(TypeError, match=r"_Loose.__init__ takes \*options"):
        _Loose(alpha=1).hyperparameters()


def test_anime_graph_keeps_each_argument_under_its_name() -> None:
    engine = AnimeGraphEngine(clusters=7, max_tile=3, seed=4, graph="clustered")
    hyperparameters = engine.hyperparameters()
    assert len(hyperparameters) == 10
    assert (hyperparameters["clusters"], hyperparameters["max_tile"]) == (7, 3)
    assert (hyperparameters["seed"], hyperparameters["graph"]) == (4, "clustered")
    assert hyperparameters["variance"] == 0.95 and hyperparameters["use_audio"] is True


@pytest.mark.parametrize("name", engine_names())
def test_an_engine_rebuilt_from_its_hyperparameters_is_the_same(name: str) -> None:
    engine = get_engine_class(name)()
    rebuilt = type(engine)(**engine.hyperparameters())
    assert vars(rebuilt) == vars(engine)


@pytest.mark.parametrize("name", engine_names())
def test_fit_leaves_the_engine_unchanged(name: str) -> None:
    engine = get_engine_class(name)()
    before = copy.deepcopy(vars(engine))
    model = engine.fit(make_corpus(seed=3, n_utterances=6))
    assert vars(engine) == before
    assert model.manifest.hyperparameters == before


class _Recording(SpanSynthesizer):
    def __init__(self) -> None:
        super().__init__()
        self.seen: list[tuple[str, float, int | None]] = []

    def _accepted(self, span: PhonemeSpan, sent: int | None) -> None:
        self.seen.append((span.phoneme, span.start, sent))

    def frames(self) -> Any:
        return None

    def finish(self) -> Any:
        return None


def test_accepted_spans_carry_their_client_index_and_filled_silences_none() -> None:
    synthesizer = _Recording()
    synthesizer.feed([("AA", 0.0, 0.1), ("B", 0.3, 0.4)])
    synthesizer.feed([("sil", 0.4, 0.5), ("M", 0.7, 0.8)])
    assert synthesizer.seen == [
        ("AA", 0.0, 0),
        ("sil", 0.1, None),
        ("B", 0.3, 1),
        ("sil", 0.4, 2),
        ("sil", 0.5, None),
        ("M", 0.7, 3),
    ]
    assert synthesizer.sent == 4 and len(synthesizer.spans) == 6
    with pytest.raises(InvalidRequestError) as caught:  # errors name the index as sent
        synthesizer.feed([("AA", 0.9, 1.0), ("AA", 0.95, 0.99)])
    assert caught.value.where == "spans[5]"
