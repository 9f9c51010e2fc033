"""Word timings end to end: the SDK's ``send_words`` against a real uvicorn server on
loopback, chunk by chunk as a TTS sends them, cut inside words, gives the frames of the
whole words each chunk completes sent as phonemes; ``POST /v1/synthesize`` with ``words``
gives the frames of the same timings sent whole as phonemes, German words (``voice``
"de") included, whose phonemes land near espeak-ng's own."""

from __future__ import annotations

import json
import shutil
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest

from lipstream.bench import tts_shapes
from lipstream.frontends.formats import parse_timings
from lipstream.frontends.word_durations import WordDurationModel
from lipstream.frontends.words_to_spans import timings_to_spans
from lipstream.speech.spoken_words import speak_words
from lipstream.timeline import PhonemeSpan
from lipstream_client import Client
from tests.lipstream.server.harness import Served, serving

FPS = 50.0
TEXT = "Map the bay "
STEP_S = 0.07
WORD_TIMING_MEDIAN_MS = 20.0


def _alignment(text: str, first: int) -> dict[str, Any]:
    return {
        "characters": list(text),
        "character_start_times_seconds": [round((first + i) * STEP_S, 3) for i in range(len(text))],
        "character_end_times_seconds": [
            round((first + i + 1) * STEP_S, 3) for i in range(len(text))
        ],
    }


@pytest.fixture(scope="module")
def served(words_models: Path) -> Iterator[Served]:
    with serving(words_models) as server:
        yield server


def _expected_spans(
    words_models: Path, groups: tuple[tuple[int, int], ...] = ((0, len(TEXT)),)
) -> list[dict[str, Any]]:
    """The spans of ``TEXT``'s characters from ``begin`` to ``end``, group after group, each
    spread on its own from where the previous ended."""
    durations = WordDurationModel.load(words_models / "viseme-lerp")
    spans: list[PhonemeSpan] = []
    for begin, end in groups:
        timings = parse_timings({"alignment": _alignment(TEXT[begin:end], begin)})
        spans += timings_to_spans(timings, durations, after=spans[-1].end if spans else 0.0)
    return [{"phoneme": s.phoneme, "start": s.start, "end": s.end} for s in spans]


def test_words_sent_in_chunks_cut_inside_words_give_the_frames_of_the_words_completed(
    served: Served, words_models: Path
) -> None:
    cuts = [0, 5, 9, len(TEXT)]  # "Map t" | "he b" | "ay ": each completes one word
    completed = ((0, 3), (4, 7), (8, len(TEXT)))  # "Map", "the", "bay "
    with Client(served.ws) as client:
        stream = client.start("viseme-lerp", "demo", fps=FPS)
        for begin, end in zip(cuts, cuts[1:]):
            stream.send_words({"alignment": _alignment(TEXT[begin:end], begin)}, "elevenlabs")
        stream.end()
        chunked = stream.collect(timeout=30)
        whole = client.start("viseme-lerp", "demo", fps=FPS)
        whole.send_phonemes(
            [(s["phoneme"], s["start"], s["end"]) for s in _expected_spans(words_models, completed)]
        )
        whole.end()
        reference = whole.collect(timeout=30)
    assert chunked.done.stats.frames == reference.done.stats.frames
    np.testing.assert_array_equal(np.asarray(chunked.rows()), np.asarray(reference.rows()))


def test_rest_takes_words_instead_of_items(served: Served, words_models: Path) -> None:
    body = {"engine": "viseme-lerp", "character": "demo", "fps": FPS}
    timings = {"alignment": _alignment(TEXT, 0)}
    by_words = httpx.post(
        f"{served.http}/v1/synthesize",
        content=json.dumps({**body, "words": {"timings": timings, "format": "elevenlabs"}}),
        headers={"Content-Type": "application/json"},
    )
    by_items = httpx.post(
        f"{served.http}/v1/synthesize",
        content=json.dumps({**body, "items": _expected_spans(words_models)}),
        headers={"Content-Type": "application/json"},
    )
    assert by_words.status_code == 200, by_words.text
    assert by_words.json()["data"] == by_items.json()["data"]


@pytest.mark.parametrize(
    ("words", "status", "code"),
    [
        ({"timings": {"nothing": 1}}, 400, "unknown_timing_format"),
        ({"timings": [{"word": "a", "start": 0.5, "end": 0.1}]}, 400, "invalid_times"),
        ({"timings": [], "format": "klingon"}, 400, "invalid_message"),
        ("not an object", 400, "invalid_message"),
    ],
)
def test_rest_refuses_bad_words_with_their_code(
    served: Served, words: Any, status: int, code: str
) -> None:
    answer = httpx.post(
        f"{served.http}/v1/synthesize",
        content=json.dumps({"engine": "viseme-lerp", "character": "demo", "words": words}),
        headers={"Content-Type": "application/json"},
    )
    assert (answer.status_code, answer.json()["error"]["code"]) == (status, code)
    assert httpx.get(f"{served.http}/healthz").status_code == 200


@pytest.mark.skipif(shutil.which("espeak-ng") is None, reason="espeak-ng missing")
def test_rest_takes_german_words_with_their_voice(served: Served, words_models: Path) -> None:
    spoken = speak_words(["Die Kinder spielen im Garten mit dem Ball."], voice="de")[0]
    timings = tts_shapes.words_input(spoken)
    body = {"engine": "viseme-lerp", "character": "demo", "fps": FPS}
    by_words = httpx.post(
        f"{served.http}/v1/synthesize",
        json={**body, "words": {"timings": timings, "format": "words", "voice": "de"}},
    )
    assert by_words.status_code == 200, by_words.text
    durations = WordDurationModel.load(words_models / "viseme-lerp")
    spans = timings_to_spans(parse_timings(timings), durations, voice="de")
    # The derived phonemes are espeak-ng's own German ones, near its own onsets.
    errors_ms = np.array(tts_shapes.onset_errors(spoken.words, spans)) * 1000
    assert len(errors_ms) > 0.8 * sum(len(word.phonemes) for word in spoken.words)
    assert np.median(errors_ms) <= WORD_TIMING_MEDIAN_MS
    items = [{"phoneme": s.phoneme, "start": s.start, "end": s.end} for s in spans]
    by_items = httpx.post(f"{served.http}/v1/synthesize", json={**body, "items": items})
    assert by_words.json()["data"] == by_items.json()["data"]
