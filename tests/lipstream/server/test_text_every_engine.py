"""Text on every engine, as a new user sends it: no options, the real SDK, a real
``lipstream serve`` on loopback. Each engine's frames equal what its model makes offline of
espeak-ng's own spans and speech, handed over together (so ``hmm`` with a vocal model is
driven by both, as a text request must be), and then the face settles to the character's
rest pose: the model's face in the middle of a second of silence."""

from __future__ import annotations

import shutil
from collections.abc import Iterator

import numpy as np
import pytest

from lipstream.engines import engine_names
from lipstream.engines.base import Model, frame_count
from lipstream.speech.text_frontend import speak_text
from lipstream_client import Client, StreamResult
from tests.helpers import rest_pose
from tests.live_server import LiveServer, live_server, save_models

pytestmark = pytest.mark.skipif(shutil.which("espeak-ng") is None, reason="espeak-ng missing")

FPS = 60.0
SENTENCE = "Hello there, my name is Mia."
SETTLE_FRAMES = 9  # the default return to rest, 150 ms at 60 fps


@pytest.fixture(scope="module")
def served(
    trained_models: dict[str, Model], tmp_path_factory: pytest.TempPathFactory
) -> Iterator[LiveServer]:
    with live_server(save_models(trained_models, tmp_path_factory.mktemp("models"))) as server:
        yield server


def say(served: LiveServer, engine: str, text: str, lang: str | None = None) -> StreamResult:
    with Client(served.ws) as client:
        stream = client.start(engine, "demo", fps=FPS)
        stream.send_text(text, lang=lang)
        stream.end()
        return stream.collect(timeout=60)


def test_the_hmm_under_test_hears_audio(trained_models: dict[str, Model]) -> None:
    # The defect needs a model that takes both inputs: hmm trained with its vocal model.
    assert trained_models["hmm"].uses_audio


def smoothstep_to(face: np.ndarray, rest: np.ndarray, steps: int) -> np.ndarray:
    u = np.arange(1, steps + 1) / steps
    weights = u * u * (3 - 2 * u)
    return np.stack([face + (rest - face) * w for w in weights])


@pytest.mark.parametrize("engine", engine_names())
def test_text_with_no_options_plays_on_every_engine_and_ends_at_rest(
    served: LiveServer, trained_models: dict[str, Model], engine: str
) -> None:
    result = say(served, engine, SENTENCE)
    spoken = speak_text(SENTENCE)  # a fresh espeak-ng worker says the same
    duration = len(spoken.pcm16) / 2 / spoken.sample_rate
    spoken_frames = frame_count(duration, FPS)
    assert result.done.reason == "end"
    assert result.done.stats.frames == spoken_frames + SETTLE_FRAMES
    synthesis_ms = result.done.stats.speech_synthesis_ms  # reported apart from the lag
    assert synthesis_ms is not None and synthesis_ms > 0
    assert result.speech_pcm16() == spoken.pcm16
    model = trained_models[engine]
    offline = model.synthesize(
        spoken.spans,
        fps=FPS,
        audio=spoken.audio if model.uses_audio else None,
        emotion=None,
        **dict(result.ready.options),
    ).frames
    rows = np.asarray(result.rows(), dtype=np.float32)
    assert rows.shape == (spoken_frames + SETTLE_FRAMES, len(model.channels))
    assert np.allclose(rows[:spoken_frames], offline, atol=1e-5)
    rest = rest_pose(model, result.ready.emotion)
    assert np.array_equal(rows[-1], rest)
    settle = smoothstep_to(offline[-1].astype(np.float64), rest.astype(np.float64), SETTLE_FRAMES)
    assert np.allclose(rows[spoken_frames:], settle, atol=1e-5)


@pytest.mark.parametrize("engine", engine_names())
def test_text_in_another_language_plays_on_every_engine(
    served: LiveServer, trained_models: dict[str, Model], engine: str
) -> None:
    text, lang = "Schöne Grüße aus München!", "de"
    result = say(served, engine, text, lang)
    spoken = speak_text(text, lang=lang)
    spoken_frames = frame_count(len(spoken.pcm16) / 2 / spoken.sample_rate, FPS)
    assert result.done.reason == "end" and result.speech_pcm16() == spoken.pcm16
    model = trained_models[engine]
    offline = model.synthesize(
        spoken.spans,
        fps=FPS,
        audio=spoken.audio if model.uses_audio else None,
        emotion=None,
        **dict(result.ready.options),
    ).frames
    rows = np.asarray(result.rows(), dtype=np.float32)
    assert np.allclose(rows[:spoken_frames], offline, atol=1e-5)
