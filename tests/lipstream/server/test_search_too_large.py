"""PQ-Matching past its cap is refused as soon as the phonemes arrive, before more search.

With one phoneme per message and ``pq_window`` 4 (at most 64 phonemes), the
server once searched a window for every message it had queued and refused
only the 65th phoneme, after seconds of search. Here the server's PQ window
search is wrapped to count its calls, and each call runs until its request's
work is stopped (checking as the real search does, every few steps, for at
most ``HOLD_S``), so that every later message is certainly read ahead while
it runs. Once the phonemes waiting cross the cap, the running search
stops and the request ends with ``search_too_large``: at most that one window
was searched, where the old code searched one per message (61). The same on
the sans-I/O session: phonemes reported waiting past the cap stop the
request's work, and its next message ends it, nothing searched.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from lipstream.engines.anime_graph import synthesizer
from lipstream.engines.anime_graph.pq import pq_window
from lipstream.engines.base import Model
from lipstream.server.catalog import Catalog
from lipstream.server.request import RequestLimits
from lipstream.server.session import Session, SessionLimits
from lipstream_client import Done, End, ErrorMessage, PhonemeItem, Phonemes, Ready, Start
from lipstream_client.messages import JsonValue
from tests.lipstream.server.harness import client, serving

HOLD_S = 20.0  # a bound on a stalled machine, not a speed
WINDOW = 4
ALLOWED = 64  # 256 window × phonemes
LABELS = ("AA", "M", "S", "IY")


@pytest.fixture(scope="module")
def anime_dir(trained_models: dict[str, Model], tmp_path_factory: pytest.TempPathFactory) -> Path:
    directory = tmp_path_factory.mktemp("server-models-anime")
    trained_models["anime-graph"].save(directory / "anime-graph")
    return directory


class Searches:
    """The PQ windows searched; while ``hold``, a search lasts until its work is stopped."""

    def __init__(self) -> None:
        self.calls = 0
        self.hold = True
        self.lock = threading.Lock()


@pytest.fixture
def searches(monkeypatch: pytest.MonkeyPatch) -> Searches:
    real = pq_window
    searched = Searches()

    def counted(*args: Any) -> Any:
        check: Callable[[], None] = args[-1]
        with searched.lock:
            searched.calls += 1
        deadline = time.monotonic() + HOLD_S
        while searched.hold and time.monotonic() < deadline:
            check()  # raises once the request's work is stopped
            time.sleep(0.001)
        return real(*args)

    monkeypatch.setattr(synthesizer, "pq_window", counted)
    return searched


def one_phoneme_messages(identifier: str, count: int) -> list[Phonemes]:
    return [
        Phonemes(identifier, (PhonemeItem(LABELS[i % 4], 0.08 * i, 0.08 * (i + 1)),))
        for i in range(count)
    ]


def test_pq_past_its_cap_is_refused_before_searching_the_queued_phonemes(
    anime_dir: Path, searches: Searches
) -> None:
    options: dict[str, JsonValue] = {"search": "pq", "pq_window": WINDOW}
    with serving(anime_dir) as served, client(served.ws, max_queue=None) as ws:
        ws.send(Start("a", "anime-graph", "demo", options=options))
        ws.send(*one_phoneme_messages("a", ALLOWED + 6), End("a"))
        answers = ws.until_done("a")
        error = answers[-1]
        assert isinstance(error, ErrorMessage), error
        assert (error.code, error.id, error.fatal) == ("search_too_large", "a", True)
        assert error.message.startswith("options.search: ")
        assert searches.calls <= 1  # the window running when the cap was crossed, if any
        # A request within the cap is searched and finishes on the same connection.
        searches.hold = False
        before = searches.calls
        ws.send(Start("b", "anime-graph", "demo", options=options))
        ws.send(*one_phoneme_messages("b", 8), End("b"))
        assert isinstance(ws.until_done("b")[-1], Done)
    assert searches.calls > before


def test_phonemes_waiting_past_the_cap_end_the_request_at_its_next_message(
    catalog: Catalog, searches: Searches
) -> None:
    searches.hold = False
    session = Session(catalog, SessionLimits(2, RequestLimits(1000, 100_000, 100.0)))
    options: dict[str, JsonValue] = {"search": "pq", "pq_window": WINDOW}
    messages = one_phoneme_messages("a", ALLOWED + 1)
    assert isinstance(
        session.handle(Start("a", "anime-graph", "demo", options=options), 0.0)[0].message, Ready
    )
    for message in messages[:3]:  # fewer than a window: nothing searched yet
        session.handle(message, 0.0)
    session.check_queued("a", ALLOWED - 3)  # at the cap: nothing happens
    assert not session.requests["a"].guard.cancelled
    session.check_queued("a", ALLOWED - 2)
    assert session.requests["a"].guard.cancelled  # the running work stops at its next step
    [answer] = session.handle(messages[3], 0.0)
    error = answer.message
    assert isinstance(error, ErrorMessage)
    assert (error.code, error.id, error.fatal) == ("search_too_large", "a", True)
    assert "at most 64 phonemes" in error.message
    assert searches.calls == 0
    assert session.active_requests == 0
