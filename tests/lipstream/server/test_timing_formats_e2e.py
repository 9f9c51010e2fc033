"""Every timing format drives every engine: one real uvicorn server on loopback holds the
demo character's model of each engine; the same short utterance ("map the bay", ending
at ``END_S``), written by hand in each TTS's shape, goes in over REST (``words``) and over
the WebSocket (the SDK's ``send_words``), and ``lipstream synth --words`` reads each as a
file. The frames are finite and as many as the protocol says: one at every ``i / fps``
up to the last time in the input, then the return to rest (REST and WebSocket). A text
in each of the issue's twelve languages goes to every engine over REST, and its frames
span no more than the speech that comes back with them."""

from __future__ import annotations

import base64
import json
import math
import shutil
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest

from lipstream.cli import main
from lipstream.engines import engine_names
from lipstream_client import Client
from tests.helpers import return_frames
from tests.lipstream.frontends.test_languages import LANGUAGES
from tests.lipstream.server.harness import Served, fixed_calibration, serving

pytestmark = pytest.mark.skipif(shutil.which("espeak-ng") is None, reason="espeak-ng missing")

FPS = 50.0
END_S = 0.95  # 47.5 frame periods: the last frame is at 47 / fps, nowhere near a tie
TICKS_PER_S = 10_000_000

# (word, start s, end s); a pause between "map" and "the" becomes silence.
WORDS = (("map", 0.10, 0.42), ("the", 0.48, 0.58), ("bay", 0.60, END_S))
# The characters of each word with their times, spaces over the gaps.
CHARACTERS = (
    ("m", 0.10, 0.20),
    ("a", 0.20, 0.32),
    ("p", 0.32, 0.42),
    (" ", 0.42, 0.48),
    ("t", 0.48, 0.51),
    ("h", 0.51, 0.53),
    ("e", 0.53, 0.58),
    (" ", 0.58, 0.60),
    ("b", 0.60, 0.70),
    ("a", 0.70, 0.85),
    ("y", 0.85, END_S),
)
# Cartesia's IPA phonemes of the same words, back to back within each word.
IPA = (
    ("m", 0.10, 0.20),
    ("æ", 0.20, 0.32),
    ("p", 0.32, 0.42),
    ("ð", 0.48, 0.53),
    ("ə", 0.53, 0.58),
    ("b", 0.60, 0.70),
    ("eɪ", 0.70, END_S),
)


def _ticks(seconds: float) -> int:
    return round(seconds * TICKS_PER_S)


def _words() -> list[dict[str, Any]]:
    return [{"word": word, "start": start, "end": end} for word, start, end in WORDS]


def _elevenlabs() -> dict[str, Any]:
    return {
        "alignment": {
            "characters": [c for c, _, _ in CHARACTERS],
            "character_start_times_seconds": [start for _, start, _ in CHARACTERS],
            "character_end_times_seconds": [end for _, _, end in CHARACTERS],
        }
    }


def _azure() -> list[dict[str, Any]]:
    events: list[dict[str, Any]] = []
    offset = 0
    for word, start, end in WORDS:
        events.append(
            {
                "audioOffset": _ticks(start),
                "duration": _ticks(end - start),
                "text": word,
                "textOffset": offset,
                "wordLength": len(word),
                "boundaryType": "WordBoundary",
            }
        )
        offset += len(word) + 1
    return events


def _polly() -> str:
    marks: list[dict[str, Any]] = []
    offset = 0
    for word, start, _ in WORDS:
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
    marks.append({"time": round(END_S * 1000), "type": "viseme", "value": "sil"})
    return "\n".join(json.dumps(mark) for mark in marks) + "\n"


def _ipa() -> dict[str, Any]:
    return {
        "phonemes": [p for p, _, _ in IPA],
        "start": [start for _, start, _ in IPA],
        "end": [end for _, _, end in IPA],
    }


TIMINGS: dict[str, Any] = {
    "words": _words(),
    "elevenlabs": _elevenlabs(),
    "azure": _azure(),
    "polly": _polly(),
    "ipa": _ipa(),
}
# Frames at i / fps for i = 0 .. floor(END_S × fps), then the return to rest.
INPUT_FRAMES = math.floor(END_S * FPS) + 1
STREAM_FRAMES = INPUT_FRAMES + return_frames(FPS)


@pytest.fixture(scope="module")
def served(all_models_dir: Path) -> Iterator[Served]:
    with fixed_calibration(), serving(all_models_dir) as server:
        yield server


def _rest(served: Served, engine: str, timing_format: str) -> tuple[np.ndarray, int]:
    answer = httpx.post(
        f"{served.http}/v1/synthesize",
        json={
            "engine": engine,
            "character": "demo",
            "fps": FPS,
            "words": {"timings": TIMINGS[timing_format], "format": timing_format},
        },
        timeout=120,
    )
    assert answer.status_code == 200, answer.text
    result = answer.json()
    return np.array(result["data"], dtype=np.float32), int(result["stats"]["frames"])


def _websocket(served: Served, engine: str, timing_format: str) -> tuple[np.ndarray, int]:
    with Client(served.ws) as client:
        stream = client.start(engine, "demo", fps=FPS)
        stream.send_words(TIMINGS[timing_format], timing_format)
        stream.end()
        result = stream.collect(timeout=120)
    return np.asarray(result.rows(), dtype=np.float32), result.done.stats.frames


@pytest.mark.parametrize("timing_format", sorted(TIMINGS))
@pytest.mark.parametrize("engine", engine_names())
def test_every_format_drives_every_engine_over_rest_and_the_websocket(
    served: Served, engine: str, timing_format: str
) -> None:
    by_rest, rest_count = _rest(served, engine, timing_format)
    by_socket, socket_count = _websocket(served, engine, timing_format)
    for frames, count in ((by_rest, rest_count), (by_socket, socket_count)):
        assert frames.ndim == 2 and frames.shape[1] > 0
        assert (len(frames), count) == (STREAM_FRAMES, STREAM_FRAMES)
        assert np.isfinite(frames).all()
    # The mouth moves: the frames over the words are not all one pose.
    assert np.ptp(by_rest[:INPUT_FRAMES], axis=0).max() > 0.0
    np.testing.assert_array_equal(by_rest, by_socket)


@pytest.mark.parametrize("timing_format", sorted(TIMINGS))
def test_synth_reads_every_format_from_a_file(
    all_models_dir: Path, tmp_path: Path, timing_format: str
) -> None:
    timings = TIMINGS[timing_format]
    source = tmp_path / "timings.txt"
    source.write_text(timings if isinstance(timings, str) else json.dumps(timings), "utf-8")
    out = tmp_path / "frames.json"
    model = str(all_models_dir / "viseme-lerp")
    arguments = ["synth", "--model", model, "--words", str(source), "--out", str(out)]
    status = main([*arguments, "--words-format", timing_format, "--fps", str(FPS)])
    assert status in (0, None)
    frames = np.array(json.loads(out.read_text(encoding="utf-8"))["frames"], dtype=np.float64)
    assert len(frames) == INPUT_FRAMES
    assert np.isfinite(frames).all()


@pytest.mark.parametrize("engine", engine_names())
def test_every_language_speaks_through_every_engine_over_rest(served: Served, engine: str) -> None:
    for lang, text, _ in LANGUAGES:
        body = {"engine": engine, "character": "demo", "fps": FPS, "text": text, "lang": lang}
        answer = httpx.post(f"{served.http}/v1/synthesize", json=body, timeout=120)
        assert answer.status_code == 200, (lang, answer.text)
        result = answer.json()
        frames = np.array(result["data"], dtype=np.float32)
        speech_s = len(base64.b64decode(result["speech"]["pcm16"])) / 2
        speech_s /= result["speech"]["sample_rate"]
        assert len(frames) == result["stats"]["frames"]
        assert (
            return_frames(FPS) + 1
            < len(frames)
            <= math.floor(speech_s * FPS) + 1 + return_frames(FPS)
        )
        assert np.isfinite(frames).all(), lang
        assert np.ptp(frames, axis=0).max() > 0.0, lang
