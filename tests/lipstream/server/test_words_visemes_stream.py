"""Azure and Polly word timings with visemes, streamed with the SDK's ``send_words`` to a
real uvicorn server on loopback: cut into two chunks at every event, and into one chunk
per event, a request gives the frames of the same events sent in one chunk, so a word's
visemes may come in a later chunk than the word; a viseme that comes after its word was
released (out of time order) ends the request with ``non_monotonic_times``.

Every phoneme of the sentence has its viseme event, so each phoneme's onset is fixed by
the events alone and the one-chunk request is the expectation whatever the duration
model (a phoneme the visemes do not anchor is placed by a model that reads its
neighbours, which one chunk and several see differently).
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from lipstream.frontends.lexicon import pronounce
from lipstream.frontends.viseme_anchors import VISEME_OF
from lipstream_client import Client, LipstreamServerError
from tests.lipstream.server.harness import Served, serving

FPS = 50.0
PHONEME_S = 0.08
# Words and the pause after each (s); "made" is followed by a pause (Polly: a sil mark).
SENTENCE = (("Bob", 0.0), ("made", 0.15), ("a", 0.0), ("map", 0.0), ("by", 0.0), ("moon", 0.0))
LEAD_S = 0.1
TICKS_PER_S = 10_000_000


def _timed_words() -> list[tuple[str, float, float, list[tuple[str, float]]]]:
    """(word, start, end, [(phoneme, onset)]) of the sentence, phonemes ``PHONEME_S`` each."""
    words = [word for word, _ in SENTENCE]
    laid = []
    clock = LEAD_S
    for (word, pause), phonemes in zip(SENTENCE, pronounce(words)):
        onsets = [(phoneme, round(clock + i * PHONEME_S, 3)) for i, phoneme in enumerate(phonemes)]
        end = round(clock + len(phonemes) * PHONEME_S, 3)
        laid.append((word, round(clock, 3), end, onsets))
        clock = end + pause
    return laid


def ticks(seconds: float) -> int:
    return round(seconds * TICKS_PER_S)


def is_word(event: dict[str, Any]) -> bool:
    """An Azure word boundary or a Polly word mark."""
    return "text" in event or event.get("type") == "word"


def azure_events() -> list[dict[str, Any]]:
    """Word boundaries (with durations) and viseme events in time order, viseme 0 (silence)
    at the start and the end."""
    events: list[dict[str, Any]] = [{"audioOffset": 0, "visemeId": 0}]
    offset = 0
    words = _timed_words()
    for word, start, end, phonemes in words:
        events.append(
            {
                "audioOffset": ticks(start),
                "duration": ticks(end - start),
                "text": word,
                "textOffset": offset,
                "wordLength": len(word),
                "boundaryType": "WordBoundary",
            }
        )
        offset += len(word) + 1
        for phoneme, onset in phonemes:
            events.append(
                {"audioOffset": ticks(onset), "visemeId": int(VISEME_OF["azure"][phoneme])}
            )
    events.append({"audioOffset": ticks(words[-1][2]), "visemeId": 0})
    return events


def polly_marks() -> list[dict[str, Any]]:
    """Word and viseme marks in time order (ms), a ``sil`` mark at each pause and the end."""
    marks: list[dict[str, Any]] = []
    offset = 0
    for (word, start, end, phonemes), (_, pause) in zip(_timed_words(), SENTENCE):
        marks.append(
            {
                "time": round(start * 1000),
                "type": "word",
                "start": offset,
                "end": offset + len(word),
                "value": word,
            }
        )
        offset += len(word) + 1
        for phoneme, onset in phonemes:
            marks.append(
                {
                    "time": round(onset * 1000),
                    "type": "viseme",
                    "value": VISEME_OF["polly"][phoneme],
                }
            )
        if pause > 0:
            marks.append({"time": round(end * 1000), "type": "viseme", "value": "sil"})
    marks.append({"time": round(_timed_words()[-1][2] * 1000), "type": "viseme", "value": "sil"})
    return marks


EVENTS = {"azure": azure_events(), "polly": polly_marks()}


def _chunk(timing_format: str, events: list[dict[str, Any]]) -> Any:
    """One chunk as the provider's SDK hands it over: Azure a list of events, Polly JSON
    lines."""
    if timing_format == "polly":
        return "".join(json.dumps(mark) + "\n" for mark in events)
    return events


def _frames(client: Client, timing_format: str, chunks: list[list[dict[str, Any]]]) -> np.ndarray:
    stream = client.start("viseme-lerp", "demo", fps=FPS)
    for events in chunks:
        stream.send_words(_chunk(timing_format, events), timing_format)
    stream.end()
    result = stream.collect(timeout=30)
    assert result.done.reason == "end"
    rows = np.asarray(result.rows())
    assert result.done.stats.frames == len(rows)
    return rows


@pytest.fixture(scope="module")
def served(words_models: Path) -> Iterator[Served]:
    with serving(words_models) as server:
        yield server


def test_the_sentence_has_a_viseme_for_every_phoneme_and_some_visemes_after_their_word() -> None:
    """The input is what the test means: a word boundary, then its visemes after it."""
    events = EVENTS["azure"]
    words = [i for i, event in enumerate(events) if is_word(event)]
    visemes = [i for i, event in enumerate(events) if "visemeId" in event]
    assert len(visemes) == 2 + sum(len(p) for *_, p in _timed_words())
    assert all(index + 1 in visemes for index in words)


@pytest.mark.parametrize("timing_format", ["azure", "polly"])
def test_two_chunks_cut_at_every_event_give_the_frames_of_one_chunk(
    served: Served, timing_format: str
) -> None:
    events = EVENTS[timing_format]
    with Client(served.ws) as client:
        whole = _frames(client, timing_format, [events])
        assert len(whole) > 2 * FPS * LEAD_S and np.ptp(whole) > 0.1
        for cut in range(1, len(events)):
            chunked = _frames(client, timing_format, [events[:cut], events[cut:]])
            np.testing.assert_array_equal(chunked, whole, err_msg=f"cut before event {cut}")


@pytest.mark.parametrize("timing_format", ["azure", "polly"])
def test_one_chunk_per_event_gives_the_frames_of_one_chunk(
    served: Served, timing_format: str
) -> None:
    events = EVENTS[timing_format]
    with Client(served.ws) as client:
        whole = _frames(client, timing_format, [events])
        one_by_one = _frames(client, timing_format, [[event] for event in events])
    np.testing.assert_array_equal(one_by_one, whole)


@pytest.mark.parametrize("timing_format", ["azure", "polly"])
def test_a_viseme_after_its_word_was_released_is_non_monotonic(
    served: Served, timing_format: str
) -> None:
    """Bob's last viseme held back until after "made" and its visemes were sent: Bob was
    released when "made" came, so the viseme is out of time order."""
    events = EVENTS[timing_format]
    second, third = [i for i, event in enumerate(events) if is_word(event)][1:3]
    late = events[second - 1]
    chunks = [events[: second - 1], events[second:third], [late], events[third:]]
    with Client(served.ws) as client:
        with pytest.raises(LipstreamServerError) as raised:
            _frames(client, timing_format, chunks)
        assert raised.value.code == "non_monotonic_times" and raised.value.fatal
        assert "viseme" in raised.value.message
        assert _frames(client, timing_format, [events]).size > 0  # the connection serves on
