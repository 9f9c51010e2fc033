"""The demo page's language and voice pickers, in Debian's headless Chromium against a real
``lipstream serve``: the pickers list what espeak-ng lists (``/v1/languages``), and a German
sentence with a voice variant goes out as a ``text`` with ``lang`` and ``voice`` and comes back
as the frames of what espeak-ng said in German."""

from __future__ import annotations

import json
import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from lipstream.corpus import Corpus
from lipstream.engines.base import Model, frame_count
from lipstream.speech.text_frontend import speak_text
from lipstream.training import train_engine
from tests.helpers import return_frames
from tests.lipstream.server.browser import CHROMIUM, WAIT_MS, opened_page
from tests.live_server import LiveServer, live_server

pytestmark = [
    pytest.mark.skipif(
        not CHROMIUM.exists() or shutil.which("espeak-ng") is None,
        reason="needs Debian's chromium and espeak-ng (README command (b) installs both)",
    ),
    pytest.mark.slow,  # trains viseme-lerp on the small demo corpus
]
GERMAN = "Schöne Grüße aus München!"
FPS = 60.0


@pytest.fixture(scope="module")
def lerp(small_demo_corpus: Corpus) -> Model:
    train, _ = small_demo_corpus.split()
    return train_engine(train, "viseme-lerp")


@pytest.fixture(scope="module")
def served(lerp: Model, tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    directory: Path = tmp_path_factory.mktemp("page-languages")
    lerp.save(directory / "viseme-lerp")
    with live_server(directory) as server:
        yield server


@pytest.fixture(scope="module")
def page(browser: Any, served: LiveServer) -> Iterator[Any]:
    with opened_page(browser, served.http + "/", 1360, 820) as page:
        page.sent = []
        page.on("websocket", lambda socket: socket.on("framesent", lambda f: page.sent.append(f)))
        yield page


def _listed(argument: str) -> list[str]:
    lines = subprocess.run(["espeak-ng", argument], capture_output=True, text=True, check=True)
    return lines.stdout.splitlines()[1:]


def test_the_pickers_offer_espeak_ngs_languages_and_variants(page: Any) -> None:
    offered = page.eval_on_selector_all("#lang option", "o => o.map(x => x.value)")
    languages = list(dict.fromkeys(line.split()[1] for line in _listed("--voices")))
    assert offered == languages
    assert page.input_value("#lang") == "en-us"
    variants = page.eval_on_selector_all("#voice option", "o => o.map(x => x.value)")
    listed = [line.split()[4].removeprefix("!v/") for line in _listed("--voices=variant")]
    assert variants[0] == "" and variants[1:] == list(dict.fromkeys(listed))


def test_a_german_sentence_in_a_chosen_voice_is_spoken_and_voiced(page: Any, lerp: Model) -> None:
    page.select_option("#engine", "viseme-lerp")
    page.fill("#fps", str(int(FPS)))
    page.select_option("#lang", "de")
    page.select_option("#voice", "f3")
    page.fill("#text", GERMAN)
    page.click("#speak")
    page.wait_for_function("window.lipstreamDemo.log.done.length > 0", timeout=WAIT_MS)
    texts = [
        json.loads(frame)
        for frame in page.sent
        if isinstance(frame, str) and '"type":"text"' in frame.replace(" ", "")
    ]
    assert [(m["text"], m["lang"], m["voice"]) for m in texts] == [(GERMAN, "de", "f3")]
    done = page.evaluate("window.lipstreamDemo.log.done.at(-1)")
    assert done["reason"] == "end"
    spoken = speak_text(GERMAN, "f3", 160, lang="de")
    duration = len(spoken.pcm16) / 2 / spoken.sample_rate
    assert done["stats"]["frames"] == frame_count(duration, FPS) + return_frames(FPS)
    frames = np.asarray(page.evaluate("window.lipstreamDemo.frames()"), dtype=np.float32)
    offline = lerp.synthesize(spoken.spans, fps=FPS).frames
    assert np.allclose(frames[: len(offline)], offline, atol=1e-5)
