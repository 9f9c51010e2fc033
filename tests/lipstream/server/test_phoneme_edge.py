"""A ``phonemes`` message's labels are normalized once, by the request at the server's edge:
an unknown one is the request's coded error there, and the engine is handed the spans as
``NormalizedSpans``, which it does not check again."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest

from lipstream import timeline
from lipstream.server import request
from lipstream.server.catalog import Catalog
from lipstream.server.request import RequestLimits
from lipstream.server.session import Session, SessionLimits
from lipstream_client import ErrorMessage, PhonemeItem, Phonemes, Start

ENGINES = ("viseme-lerp", "anime-graph", "hmm")


def counted(monkeypatch: pytest.MonkeyPatch, module: Any, name: str) -> list[str]:
    """The first argument of each call of ``module.<name>`` from now on."""
    calls: list[str] = []
    real: Callable[..., Any] = getattr(module, name)

    def spy(first: str, *args: Any, **kwargs: Any) -> Any:
        calls.append(first)
        return real(first, *args, **kwargs)

    monkeypatch.setattr(module, name, spy)
    return calls


def session_of(catalog: Catalog) -> Session:
    return Session(catalog, SessionLimits(3, RequestLimits(20, 1000, 100.0)))


@pytest.mark.parametrize("engine", ENGINES)
def test_labels_are_normalized_once_at_the_edge(
    catalog: Catalog, engine: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    at_edge = counted(monkeypatch, request, "normalize_phoneme")
    in_engine = counted(monkeypatch, timeline, "normalize_phoneme")
    checked_in_engine = counted(monkeypatch, timeline, "kept_labels")
    session = session_of(catalog)
    items = (PhonemeItem("m", 0.0, 0.1), PhonemeItem("aa1", 0.1, 0.3), PhonemeItem("sil", 0.3, 0.4))
    answers = session.handle(Start("a", engine, "demo"), 0.0)
    answers += session.handle(Phonemes("a", items), 0.0)
    assert not [a for a in answers if isinstance(a.message, ErrorMessage)]
    assert at_edge == ["m", "aa1", "sil"]
    assert in_engine == [] and checked_in_engine == []


def test_an_unknown_label_is_the_edges_coded_error_once(
    catalog: Catalog, monkeypatch: pytest.MonkeyPatch
) -> None:
    in_engine = counted(monkeypatch, timeline, "normalize_phoneme")
    session = session_of(catalog)
    session.handle(Start("a", "viseme-lerp", "demo"), 0.0)
    items = (PhonemeItem("AA", 0.0, 0.1), PhonemeItem("XQ", 0.1, 0.2))
    answers = [a.message for a in session.handle(Phonemes("a", items), 0.0)]
    errors = [a for a in answers if isinstance(a, ErrorMessage)]
    assert [(e.code, e.id, e.fatal) for e in errors] == [("unknown_phoneme", "a", True)]
    assert errors[0].message.startswith("items[1].phoneme: ")
    assert in_engine == []
