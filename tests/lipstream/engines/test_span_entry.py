"""Every engine's spans come in through ``Synthesizer.feed``, which checks each and normalizes
its label once; engines take them as they are."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest

from lipstream import timeline
from lipstream.engines.base import Model
from lipstream.errors import UnknownPhonemeError
from lipstream.timeline import NormalizedSpans, PhonemeSpan

ENGINES = ("viseme-lerp", "anime-graph", "dam", "cohen-massaro", "hmm", "expressive-dp")


def counted(monkeypatch: pytest.MonkeyPatch, name: str) -> list[str]:
    """The first argument of each call of ``timeline.<name>`` from now on."""
    calls: list[str] = []
    real: Callable[..., Any] = getattr(timeline, name)

    def spy(label: str, *args: Any, **kwargs: Any) -> Any:
        calls.append(label)
        return real(label, *args, **kwargs)

    monkeypatch.setattr(timeline, name, spy)
    return calls


@pytest.mark.parametrize("engine", ENGINES)
def test_an_unknown_label_fed_to_any_engine_is_the_coded_error_at_its_span(
    trained_models: dict[str, Model], engine: str
) -> None:
    synthesizer = trained_models[engine].start(fps=60.0)
    synthesizer.feed([("AA", 0.0, 0.1)])
    with pytest.raises(UnknownPhonemeError) as raised:
        synthesizer.feed([("B", 0.1, 0.2), ("XQ", 0.2, 0.3)])
    assert (raised.value.code, raised.value.where) == ("unknown_phoneme", "spans[2]")


@pytest.mark.parametrize("engine", ENGINES)
def test_each_raw_label_is_normalized_once_and_the_engine_takes_it_canonical(
    trained_models: dict[str, Model], engine: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    model = trained_models[engine]
    raw = [("sil", 0.0, 0.1), ("m", 0.1, 0.2), ("aa1", 0.2, 0.35), ("sil", 0.35, 0.5)]
    canonical = [
        PhonemeSpan(label, start, end)
        for label, start, end in [
            ("sil", 0.0, 0.1),
            ("M", 0.1, 0.2),
            ("AA", 0.2, 0.35),
            ("sil", 0.35, 0.5),
        ]
    ]
    normalized = counted(monkeypatch, "normalize_phoneme")
    from_raw = model.synthesize(raw, fps=60.0)
    assert normalized == ["sil", "m", "aa1", "sil"]
    from_canonical = model.synthesize(canonical, fps=60.0)
    assert normalized == ["sil", "m", "aa1", "sil"]  # canonical spans are kept as they are
    assert from_raw.frames.tobytes() == from_canonical.frames.tobytes()


@pytest.mark.parametrize("engine", ENGINES)
def test_spans_an_edge_normalized_are_not_checked_again(
    trained_models: dict[str, Model], engine: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    normalized = counted(monkeypatch, "normalize_phoneme")
    looked_up = counted(monkeypatch, "kept_labels")
    synthesizer = trained_models[engine].start(fps=60.0)
    spans = NormalizedSpans([PhonemeSpan("M", 0.0, 0.1), PhonemeSpan("AA", 0.1, 0.3)])
    synthesizer.feed(spans)
    synthesizer.finish()
    assert normalized == [] and looked_up == []
