"""The demo page's timing-file form in Debian's headless Chromium against a real
``lipstream serve``: a TTS's timing file (Polly's JSON lines) with its WAV goes out as
the audio's chunks and one ``words`` message, the WAV plays on the request's clock, and
the frames are those ``POST /v1/synthesize`` gives for the same timings; a file the
server cannot read shows its coded error."""

from __future__ import annotations

import json
import shutil
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest

from lipstream.audio import write_wav
from lipstream.speech.text_frontend import speak_text
from tests.lipstream.server.browser import CHROMIUM, WAIT_MS, opened_page
from tests.live_server import LiveServer, live_server

pytestmark = pytest.mark.skipif(
    not CHROMIUM.exists() or shutil.which("espeak-ng") is None,
    reason="needs Debian's chromium and espeak-ng (README command (b) installs both)",
)
FPS = 60
POLLY = (
    '{"time":50,"type":"word","start":0,"end":4,"value":"Mary"}\n'
    '{"time":420,"type":"word","start":5,"end":8,"value":"had"}\n'
    '{"time":800,"type":"viseme","value":"sil"}\n'
)


@pytest.fixture(scope="module")
def served(words_models: Path) -> Iterator[LiveServer]:
    with live_server(words_models) as server:
        yield server


@pytest.fixture()
def page(browser: Any, served: LiveServer) -> Iterator[Any]:
    with opened_page(browser, served.http + "/") as page:
        page.sent = []
        page.on(
            "websocket", lambda ws: ws.on("framesent", lambda payload: page.sent.append(payload))
        )
        yield page


def play_timings(page: Any, timings: Path, wav: Path | None) -> None:
    page.select_option("#engine", "viseme-lerp")
    page.fill("#fps", str(FPS))
    page.set_input_files("#timing-file", str(timings))
    if wav is not None:
        page.set_input_files("#timing-wav-file", str(wav))
    page.click("#play-timings")


def test_a_timing_file_with_its_wav_plays_in_step(
    page: Any, served: LiveServer, tmp_path: Path
) -> None:
    timings = tmp_path / "marks.txt"
    timings.write_text(POLLY, encoding="utf-8")
    wav = tmp_path / "mary.wav"
    write_wav(wav, speak_text("Mary had").audio)
    play_timings(page, timings, wav)
    page.wait_for_function("window.lipstreamDemo.log.done.length === 1", timeout=WAIT_MS)
    assert page.text_content("#errors") == ""
    sent = [json.loads(frame) for frame in page.sent]
    kinds = [message["type"] for message in sent]
    assert kinds[0] == "start" and kinds[-1] == "end"
    assert kinds[1:-2] == ["audio"] * (len(kinds) - 3) and kinds[-2] == "words"
    assert len(kinds) > 3  # the WAV went out as audio chunks before the words
    words = sent[-2]
    assert words["format"] == "auto"
    assert words["timings"] == POLLY  # JSON lines go as the file's text
    assert page.evaluate("window.lipstreamDemo.request().sources.length") == 1  # the WAV
    frames = page.evaluate("window.lipstreamDemo.frames()")
    rest = httpx.post(
        f"{served.http}/v1/synthesize",
        content=json.dumps(
            {
                "engine": "viseme-lerp",
                "character": "demo",
                "fps": FPS,
                "words": {"timings": POLLY, "format": "polly"},
            }
        ),
        headers={"Content-Type": "application/json"},
        timeout=30,
    )
    assert rest.status_code == 200, rest.text
    expected = np.asarray(rest.json()["data"])
    assert len(frames) == len(expected)
    np.testing.assert_allclose(np.asarray(frames), expected, atol=1e-6)


def test_a_timing_file_the_server_cannot_read_shows_its_code(page: Any, tmp_path: Path) -> None:
    timings = tmp_path / "bad.json"
    timings.write_text('{"nothing": 1}', encoding="utf-8")
    play_timings(page, timings, None)
    page.wait_for_function(
        "document.getElementById('errors').textContent.includes('unknown_timing_format')",
        timeout=WAIT_MS,
    )
    assert page.text_content("#status") == "ended by an error"
