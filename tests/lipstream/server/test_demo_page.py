"""The demo page ``/`` in headless Chromium against a real server: it loads offline, speaks
typed text, moves the face, follows the engine control and shows the server's errors.

Debian's ``chromium`` (README command (b) installs it) is driven by Playwright's Python
package through ``executable_path``: nothing is downloaded. One browser and one server
serve the whole module. Set ``LIPSTREAM_DEMO_SCREENSHOT`` to a path to keep the
screenshot the typing test takes mid-sentence, on an open vowel; the README's
``bench/demo-page.png`` is the same view taken the same way of ``lipstream serve`` with
the full demo character (engine ``anime-graph``).
"""

from __future__ import annotations

import os
import re
import shutil
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from lipstream.engines import engine_names
from lipstream.engines.base import Model
from tests.helpers import rest_pose
from tests.lipstream.server.browser import CHROMIUM, WAIT_MS, opened_page
from tests.live_server import LiveServer, live_server

SENTENCE = "Hello there, my name is Mia."
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
SETTLE_FRAMES = 9  # after `end`, the face returns to rest over 150 ms: 9 frames at 60 fps

pytestmark = pytest.mark.skipif(
    not CHROMIUM.exists() or shutil.which("espeak-ng") is None,
    reason="needs Debian's chromium and espeak-ng (README command (b) installs both)",
)


@pytest.fixture(scope="module")
def served(all_models_dir: Path) -> Iterator[LiveServer]:
    with live_server(all_models_dir) as server:
        yield server


@pytest.fixture()
def page(browser: Any, served: LiveServer) -> Iterator[Any]:
    with opened_page(browser, served.http + "/", 1360, 820) as page:
        yield page


def speak(page: Any, text: str, engine: str | None = None) -> dict[str, Any]:
    """Type ``text``, press Speak and wait for ``done``; the page's record of the request."""
    if engine is not None:
        page.select_option("#engine", engine)
    page.fill("#text", text)
    done_before = page.evaluate("window.lipstreamDemo.log.done.length")
    page.click("#speak")
    page.wait_for_function(f"window.lipstreamDemo.log.done.length > {done_before}", timeout=WAIT_MS)
    return dict(
        page.evaluate(
            "({frames: window.lipstreamDemo.frames(), channels: window.lipstreamDemo.channels(),"
            " done: window.lipstreamDemo.log.done.at(-1), sources: "
            "window.lipstreamDemo.request().sources.length})"
        )
    )


def test_page_loads_offline_with_every_engine_the_server_holds(
    page: Any, served: LiveServer
) -> None:
    import httpx

    engines = httpx.get(served.http + "/v1/engines", trust_env=False).json()["engines"]
    offered = page.eval_on_selector_all(
        "#engine option", "options => options.filter(o => !o.disabled).map(o => o.value)"
    )
    assert offered == [engine["name"] for engine in engines if engine["loaded"]]
    assert sorted(offered) == sorted(engine_names())
    assert page.input_value("#engine") == "anime-graph"  # the README's screenshot shows it
    assert page.eval_on_selector_all("#character option", "o => o.map(x => x.value)") == ["demo"]
    assert page.requested and all(url.startswith(served.http) for url in page.requested)


def test_typed_sentence_plays_and_moves_the_face(page: Any, tmp_path: Path) -> None:
    page.select_option("#engine", "viseme-lerp")
    page.fill("#text", SENTENCE)
    # Every mouth shape the page draws, one sample per animation frame.
    page.evaluate(
        """() => {
            window.shapes = new Set();
            const mouth = document.getElementById("mouth-opening");
            const record = () => {
                window.shapes.add(mouth.getAttribute("d"));
                requestAnimationFrame(record);
            };
            record();
        }"""
    )
    page.click("#speak")
    screenshot = Path(os.environ.get("LIPSTREAM_DEMO_SCREENSHOT") or tmp_path / "demo.png")
    page.wait_for_function("window.lipstreamDemo.mouthOpening().height > 8", timeout=WAIT_MS)
    page.screenshot(path=str(screenshot))  # mid-sentence, on an open vowel
    page.wait_for_function(
        "window.lipstreamDemo.log.done.length === 1 && "
        "document.getElementById('status').textContent === 'done'",
        timeout=WAIT_MS,
    )
    shapes = page.evaluate("window.shapes.size")
    record = page.evaluate(
        "({frames: window.lipstreamDemo.frames(), done: window.lipstreamDemo.log.done[0],"
        " audio: window.lipstreamDemo.request().sources.length})"
    )
    assert shapes > 30  # the face changed shape many times during the 1.9 s sentence
    assert record["done"]["reason"] == "end"
    assert len(record["frames"]) == record["done"]["stats"]["frames"] > 60
    assert all(row is not None for row in record["frames"])
    assert record["audio"] >= 2  # the speech, scheduled as Web Audio buffers
    assert page.text_content("#clock").startswith("audio")  # frames follow the audio clock
    assert page.text_content("#rung").startswith("lerp")
    assert "ms" in page.text_content("#latency")
    assert '"frames"' in page.text_content("#stats")
    assert page.text_content("#errors") == ""
    assert screenshot.read_bytes().startswith(PNG_SIGNATURE)


def lab_file(phoneme: str) -> dict[str, Any]:
    text = f"0.0 0.2 sil\n0.2 0.8 {phoneme}\n0.8 1.0 sil\n"
    return {"name": f"{phoneme}.lab", "mimeType": "text/plain", "buffer": text.encode()}


def mouth_height_during(page: Any, phoneme: str) -> float:
    page.set_input_files("#phones-file", files=[lab_file(phoneme)])
    done_before = page.evaluate("window.lipstreamDemo.log.done.length")
    page.click("#play-file")
    page.wait_for_function(f"window.lipstreamDemo.log.done.length > {done_before}", timeout=WAIT_MS)
    page.evaluate("window.lipstreamDemo.showAt(0.6)")
    return float(page.evaluate("window.lipstreamDemo.mouthOpening().height"))


def test_open_vowel_opens_the_mouth_and_m_closes_it(page: Any) -> None:
    page.select_option("#engine", "viseme-lerp")
    open_vowel = mouth_height_during(page, "AA")
    closed = mouth_height_during(page, "M")
    assert open_vowel > closed + 5.0  # SVG units of a 240-unit-high face


def test_switching_the_engine_changes_the_frames(page: Any) -> None:
    first = speak(page, SENTENCE, "viseme-lerp")
    second = speak(page, SENTENCE, "dam")
    assert first["done"]["stats"]["frames"] == second["done"]["stats"]["frames"]
    column = first["channels"].index("jawOpen")
    jaw_first = [row[column] for row in first["frames"]]
    jaw_second = [row[second["channels"].index("jawOpen")] for row in second["frames"]]
    assert max(abs(a - b) for a, b in zip(jaw_first, jaw_second)) > 0.02
    assert page.text_content("#errors") == ""


def test_a_server_error_is_shown_to_the_user(page: Any) -> None:
    # An engine the server does not hold (set without a change event: the character stays).
    page.evaluate(
        "const engine = document.getElementById('engine');"
        "engine.add(new Option('no-such-engine', 'no-such-engine'));"
        "engine.value = 'no-such-engine';"
    )
    page.click("#speak")
    page.wait_for_selector("#errors .error", timeout=WAIT_MS)
    page.wait_for_timeout(300)  # the messages pipelined after the start are answered too
    shown = page.locator("#errors .error").all_text_contents()
    assert len(shown) == 1 and shown[0].startswith("unknown_engine:")
    page.select_option("#engine", "viseme-lerp")
    assert speak(page, "Again.")["done"]["reason"] == "end"
    assert page.text_content("#errors") == ""


def test_every_channel_of_the_demo_character_moves_the_face(page: Any) -> None:
    from lipstream.demo.face import DEMO_CHANNELS

    unchanged = page.evaluate(
        """(channels) => {
            const face = window.lipstreamDemo.face;
            const svg = document.getElementById("face");
            face.apply({});
            const rest = svg.innerHTML;
            const still = channels.filter((name) => {
                face.apply({[name]: 1.0});
                return svg.innerHTML === rest;
            });
            face.apply({});
            return still;
        }""",
        list(DEMO_CHANNELS),
    )
    assert len(DEMO_CHANNELS) == 28 and unchanged == []


def test_a_textgrid_with_its_wav_plays_the_file(page: Any, tmp_path: Path) -> None:
    import math
    import wave

    from tests.helpers import REPO

    wav = tmp_path / "hello.wav"
    rate = 16000
    with wave.open(str(wav), "wb") as out:
        out.setnchannels(1)
        out.setsampwidth(2)
        out.setframerate(rate)
        tone = (int(8000 * math.sin(2 * math.pi * 220 * i / rate)) for i in range(int(0.7 * rate)))
        out.writeframes(b"".join(v.to_bytes(2, "little", signed=True) for v in tone))
    page.select_option("#engine", "viseme-lerp")
    page.set_input_files("#phones-file", str(REPO / "examples" / "hello.TextGrid"))
    page.set_input_files("#wav-file", str(wav))
    page.click("#play-file")
    page.wait_for_function("window.lipstreamDemo.log.done.length === 1", timeout=WAIT_MS)
    done = page.evaluate("window.lipstreamDemo.log.done[0]")
    assert done["reason"] == "end"
    # The TextGrid's 0.7 s, then the return to rest (150 ms at 60 fps).
    assert done["stats"]["frames"] == math.floor(0.7 * 60) + 1 + SETTLE_FRAMES
    assert page.evaluate("window.lipstreamDemo.request().sources.length") == 1  # the WAV
    assert page.text_content("#errors") == ""


def wait_until_played(page: Any) -> None:
    page.wait_for_function(
        "document.getElementById('status').textContent === 'done'", timeout=WAIT_MS
    )


@pytest.mark.parametrize("engine", engine_names())
def test_text_plays_on_every_engine_and_the_face_ends_at_rest(
    page: Any, trained_models: dict[str, Model], engine: str
) -> None:
    record = speak(page, SENTENCE, engine)
    wait_until_played(page)
    assert page.text_content("#errors") == ""
    assert record["done"]["reason"] == "end"
    assert len(record["frames"]) == record["done"]["stats"]["frames"] > 100
    assert all(row is not None for row in record["frames"])
    model = trained_models[engine]
    assert record["channels"] == list(model.channels)
    shown = page.evaluate("window.lipstreamDemo.faceValues()")
    rest = rest_pose(model, "neutral")  # the demo character's default emotion
    assert [shown[name] for name in model.channels] == pytest.approx(rest.tolist(), abs=1e-6)


def test_an_error_mid_request_returns_the_face_to_neutral(page: Any) -> None:
    # 300 phonemes: the page sends 256 in a first message, whose frames play, then the rest,
    # which the server refuses (an unknown phoneme) with a fatal error.
    lines = [f"{0.05 * i:.2f} {0.05 * (i + 1):.2f} {'AA' if i % 2 else 'M'}" for i in range(299)]
    lines.append("14.95 15.00 NOT_A_PHONEME")
    lab = {"name": "long.lab", "mimeType": "text/plain", "buffer": "\n".join(lines).encode()}
    page.select_option("#engine", "viseme-lerp")
    page.set_input_files("#phones-file", files=[lab])
    page.evaluate("window.lipstreamDemo.face.apply({jawOpen: 1.0})")
    page.click("#play-file")
    page.wait_for_selector("#errors .error", timeout=WAIT_MS)
    assert page.text_content("#errors .error").startswith("unknown_phoneme:")
    page.wait_for_function(
        "Object.values(window.lipstreamDemo.faceValues()).every((v) => v === 0)",
        timeout=WAIT_MS,
    )
    page.wait_for_timeout(300)  # and it stays there while the request's frames would play
    assert set(page.evaluate("Object.values(window.lipstreamDemo.faceValues())")) <= {0}


def test_readouts_round_their_numbers_and_stay_in_their_box(page: Any) -> None:
    speak(page, SENTENCE, "expressive-dp")
    stats = page.text_content("#stats")
    assert '"nodes"' in stats
    long_decimals = re.findall(r"\d+\.\d{3,}", stats + page.text_content("#rung"))
    assert long_decimals == []
    overflow = page.evaluate(
        "[...document.querySelectorAll('#readouts *')]"
        ".filter((e) => e.scrollWidth > e.clientWidth + 1 && getComputedStyle(e).overflowX !== 'visible')"
        ".map((e) => e.id || e.tagName)"
    )
    assert overflow == []
    box = page.evaluate(
        "(() => { const r = document.getElementById('readouts').getBoundingClientRect();"
        " const s = document.getElementById('stats').getBoundingClientRect();"
        " return [r.right, s.right, s.left, r.left]; })()"
    )
    assert box[3] <= box[2] and box[1] <= box[0] <= page.viewport_size["width"]


def test_the_page_asks_for_its_icon_and_gets_it(page: Any, served: LiveServer) -> None:
    import httpx

    icon = httpx.get(served.http + "/favicon.ico", trust_env=False)
    assert icon.status_code == 200 and icon.headers["content-type"] == "image/svg+xml"
    href = page.evaluate("document.querySelector('link[rel=icon]').href")
    assert httpx.get(href, trust_env=False).content == icon.content
