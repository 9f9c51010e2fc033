"""``words`` messages in the sans-I/O session: a TTS's timings drive a request as the same
spans sent as phonemes would; a word cut at a chunk's edge waits for the next chunk or the
end; frames of the words before it follow at once; bad timings end only that request."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from lipstream.config import ServerSettings
from lipstream.engines.base import frame_count
from lipstream.frontends.formats import parse_timings
from lipstream.frontends.word_durations import WordDurationModel
from lipstream.frontends.words_to_spans import timings_to_spans
from lipstream.models import ModelRegistry
from lipstream.server.catalog import Catalog
from lipstream.server.request import RequestLimits
from lipstream.server.session import Session, SessionLimits
from lipstream_client import (
    Done,
    End,
    ErrorMessage,
    Frames,
    PhonemeItem,
    Phonemes,
    Ready,
    ServerMessage,
    Start,
    Words,
)
from lipstream_client.messages import JsonValue

FPS = 50.0


@pytest.fixture(scope="module")
def words_catalog(words_models: Path) -> Catalog:
    return Catalog.build(ModelRegistry.load(words_models), ServerSettings())


def _session(catalog: Catalog) -> Session:
    return Session(catalog, SessionLimits(4, RequestLimits(400, 5000, 100.0)))


def _play(session: Session, *messages: Any) -> list[ServerMessage]:
    out = []
    for message in messages:
        out += [item.stamp(0.0).message for item in session.handle(message, 0.0)]
    return out


def _start(session: Session, identifier: str) -> Ready:
    (ready,) = _play(session, Start(identifier, "viseme-lerp", "demo", fps=FPS))
    assert isinstance(ready, Ready), ready
    return ready


def _frames(messages: list[ServerMessage]) -> np.ndarray:
    blocks = [m for m in messages if isinstance(m, Frames)]
    if not blocks:
        return np.zeros((0, 0), dtype=np.float32)
    return np.concatenate([np.frombuffer(b.data, "<f4").reshape(-1, b.n_channels) for b in blocks])


def _chars(text: str, start: float, step: float = 0.08) -> dict[str, Any]:
    return {
        "characters": list(text),
        "character_start_times_seconds": [round(start + i * step, 3) for i in range(len(text))],
        "character_end_times_seconds": [round(start + (i + 1) * step, 3) for i in range(len(text))],
    }


def test_words_drive_a_request_as_their_spans_sent_as_phonemes_would(
    words_catalog: Catalog, words_models: Path
) -> None:
    session = _session(words_catalog)
    timings: list[JsonValue] = [
        {"word": "Map", "start": 0.1, "end": 0.42},
        {"word": "the", "start": 0.6, "end": 0.75},
    ]
    _start(session, "w")
    via_words = _play(session, Words("w", timings), End("w"))
    durations = WordDurationModel.load(words_models / "viseme-lerp")
    spans = timings_to_spans(parse_timings(timings), durations)
    _start(session, "p")
    items = tuple(PhonemeItem(s.phoneme, s.start, s.end) for s in spans)
    via_phonemes = _play(session, Phonemes("p", items), End("p"))
    assert [s.phoneme for s in spans] == ["sil", "M", "AE", "P", "sil", "DH", "AH"]
    np.testing.assert_array_equal(_frames(via_words), _frames(via_phonemes))
    assert isinstance(via_words[-1], Done) and via_words[-1].reason == "end"


def test_a_word_cut_at_a_chunk_edge_waits_and_earlier_words_play_at_once(
    words_catalog: Catalog,
) -> None:
    session = _session(words_catalog)
    _start(session, "c")
    first = _play(session, Words("c", {"alignment": _chars("Hello wo", 0.0)}, "elevenlabs"))
    request = session.requests["c"].active
    assert request.phonemes_end == pytest.approx(0.4)  # "Hello": 5 characters of 80 ms
    sent = len(_frames(first))
    assert 0 < sent <= frame_count(0.4, FPS)
    second = _play(session, Words("c", {"alignment": _chars("rld", 0.64)}))
    assert second == [] and request.phonemes_end == pytest.approx(0.4)  # "world" may go on
    third = _play(session, Words("c", {"alignment": _chars(" bye", 0.88)}))
    assert request.phonemes_end == pytest.approx(0.88)  # "world" ended at 0.88 s
    last = _play(session, End("c"))
    done = last[-1]
    assert isinstance(done, Done)
    total = sent + len(_frames(second)) + len(_frames(third)) + len(_frames(last))
    assert total == done.stats.frames
    assert total >= frame_count(1.2, FPS)  # to the end of "bye", then the return to rest


def test_offset_moves_a_chunk_onto_the_utterance_clock(words_catalog: Catalog) -> None:
    session = _session(words_catalog)
    _start(session, "o")
    _play(session, Words("o", [{"word": "hi", "start": 0.0, "end": 0.3}]))
    _play(session, Words("o", [{"word": "there", "start": 0.1, "end": 0.5}], offset=0.5))
    assert session.requests["o"].active.phonemes_end == pytest.approx(1.0)


@pytest.mark.parametrize(
    ("timings", "code", "where"),
    [
        ([{"word": "a", "start": 0.1, "end": 0.05}], "invalid_times", "timings: words[0]"),
        ({"nothing": []}, "unknown_timing_format", "timings: input"),
        (
            [{"word": "—", "start": 0.0, "end": 0.2}, {"word": "b", "start": 0.1, "end": 0.3}],
            "non_monotonic_times",
            "timings: words[1]",
        ),
    ],
)
def test_bad_timings_end_only_their_request(
    words_catalog: Catalog, timings: Any, code: str, where: str
) -> None:
    session = _session(words_catalog)
    _start(session, "bad")
    _start(session, "good")
    (error,) = _play(session, Words("bad", timings))
    assert isinstance(error, ErrorMessage)
    assert (error.code, error.fatal, error.id) == (code, True, "bad")
    assert where in error.message
    assert "bad" not in session.requests and "good" in session.requests
    out = _play(session, Words("good", [{"word": "ok", "start": 0.0, "end": 0.3}]), End("good"))
    assert isinstance(out[-1], Done)


def test_timings_before_the_input_so_far_ends_are_refused(words_catalog: Catalog) -> None:
    session = _session(words_catalog)
    _start(session, "r")
    _play(session, Words("r", [{"word": "one", "start": 0.0, "end": 0.5}]))
    (error,) = _play(session, Words("r", [{"word": "two", "start": 0.2, "end": 0.6}]))
    assert isinstance(error, ErrorMessage) and error.code == "non_monotonic_times"
