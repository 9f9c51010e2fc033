"""The recording page (/record) in Debian's Chromium against a real server, its camera and
microphone fed from files made of the GRID clip ``swwp2s`` (``fake_media``).

The whole flow: a session whose sentences are the clip's transcript, one take recorded
from the fake devices for the clip's length and one too short to hold speech, both
uploaded, a training job followed to its end; then the demo page, opened from the
page's link, offers the new character and speaking a sentence with it moves the face.
Expectations come from the server's answers and the clip, not the page: the bytes the
server stored, the characters it lists, the failed take's code. Also: refused camera
permission, a browser without MediaRecorder, a clashing name, a take over the server's
size limit and a cut connection are each said in words. Set ``LIPSTREAM_RECORD_SCREENSHOT``
to a path to keep the screenshot taken while the first take records (docs/images/record.png
is that view).
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from tests.lipstream.server.browser import CHROMIUM, LAUNCH_ARGS, WAIT_MS
from tests.lipstream.server.fake_media import FakeDevices, fake_devices
from tests.live_server import LiveServer, live_server

pytest.importorskip("mediapipe", reason="capture needs the capture extra")
pytestmark = pytest.mark.skipif(
    not CHROMIUM.exists() or shutil.which("espeak-ng") is None,
    reason="needs Debian's chromium and espeak-ng (README command (b) installs both)",
)

GRID = Path(__file__).resolve().parents[2] / "data" / "grid"
CLIP = GRID / "swwp2s.mp4"
TRANSCRIPT = (GRID / "swwp2s.txt").read_text().strip()
NAME = "grid-face"
SHORT_TAKE_MS = 300  # the clip's first 0.3 s: a face, and no speech yet
MARGIN_MS = 600  # recorded beyond the clip's end, so its last word is whole
TRAINING_MS = 900_000  # capture and training on a busy machine: a bound, not a speed claim
SMALL_LIMIT = 4096  # bytes: less than a quarter second of recording
TOKEN = "record-page-token"
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
GRANTED = ["camera", "microphone"]


@pytest.fixture(scope="module")
def devices(tmp_path_factory: pytest.TempPathFactory) -> FakeDevices:
    return fake_devices(CLIP, tmp_path_factory.mktemp("fake-devices"))


@pytest.fixture(scope="module")
def camera_browser(devices: FakeDevices) -> Iterator[Any]:
    """Debian's chromium whose camera and microphone play the clip."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as playwright:
        chromium = playwright.chromium.launch(
            executable_path=str(CHROMIUM), args=LAUNCH_ARGS + devices.flags()
        )
        yield chromium
        chromium.close()


def recording_server(models: Path, recordings: Path, **settings: str) -> Iterator[LiveServer]:
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("LIPSTREAM_RECORDINGS_DIR", str(recordings))
        for name, value in settings.items():
            patch.setenv(name, value)
        with live_server(models) as running:
            yield running


@pytest.fixture(scope="module")
def served(words_models: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    """A server that trains a character from a single good take."""
    recordings = tmp_path_factory.mktemp("recordings")
    yield from recording_server(words_models, recordings, LIPSTREAM_RECORDING_MIN_TAKES="1")


@pytest.fixture(scope="module")
def guarded(words_models: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    """A server that wants a token and takes recordings of at most SMALL_LIMIT bytes."""
    recordings = tmp_path_factory.mktemp("recordings-guarded")
    yield from recording_server(
        words_models,
        recordings,
        LIPSTREAM_MAX_TAKE_BYTES=str(SMALL_LIMIT),
        LIPSTREAM_AUTH_TOKENS=TOKEN,
    )


def record_page(browser: Any, server: LiveServer, permissions: list[str], query: str = "") -> Any:
    context = browser.new_context(viewport={"width": 1400, "height": 900}, permissions=permissions)
    page = context.new_page()
    page.goto(server.http + "/record" + query)
    page.wait_for_selector("body[data-ready=true]", timeout=WAIT_MS)
    return page


def recorder(page: Any, expression: str) -> Any:
    return page.evaluate(f"window.lipstreamRecord.{expression}")


def start_session(page: Any, name: str, sentences: list[str]) -> None:
    page.fill("#name", name)
    page.click("#setup-panel summary")
    page.fill("#sentences", "\n".join(sentences))
    page.click("#create")
    page.wait_for_function("window.lipstreamRecord.state.session !== null", timeout=WAIT_MS)


def record_take(page: Any, milliseconds: int, screenshot: Path | None = None) -> None:
    """Record the current sentence for ``milliseconds`` (or until the page stops at the
    size limit) and wait for its upload to end."""
    ended = recorder(page, "log.uploads.length") + len(recorder(page, "log.errors"))
    recorded = recorder(page, "log.recorded")
    page.click("#record-take")
    page.wait_for_function(f"window.lipstreamRecord.log.recorded > {recorded}", timeout=WAIT_MS)
    if screenshot is not None:
        page.wait_for_timeout(milliseconds // 2)
        page.screenshot(path=str(screenshot))
        page.wait_for_timeout(milliseconds - milliseconds // 2)
    else:
        page.wait_for_timeout(milliseconds)
    page.evaluate("document.getElementById('stop').click()")  # unless already stopped
    page.wait_for_function(
        "window.lipstreamRecord.log.uploads.length + window.lipstreamRecord.log.errors.length"
        f" > {ended} && !window.lipstreamRecord.state.uploading",
        timeout=WAIT_MS,
    )


def row_status(page: Any, index: int) -> tuple[str, str]:
    """The take's kind (its row's class that is not ``chosen``) and status text."""
    row = page.locator(f"#takes tbody tr[data-index='{index}']")
    kinds = str(row.get_attribute("class")).split()
    return " ".join(k for k in kinds if k != "chosen"), str(row.locator(".status").inner_text())


def test_a_recorded_clip_becomes_a_character_that_speaks_a_typed_sentence(
    camera_browser: Any, served: LiveServer, devices: FakeDevices, tmp_path: Path
) -> None:
    page = record_page(camera_browser, served, GRANTED)
    start_session(page, NAME, [TRANSCRIPT, TRANSCRIPT])
    sentences = recorder(page, "state.sentences")
    assert [sentence["text"] for sentence in sentences] == [TRANSCRIPT, TRANSCRIPT]
    assert page.inner_text("#prompt") == TRANSCRIPT

    screenshot = Path(os.environ.get("LIPSTREAM_RECORD_SCREENSHOT") or tmp_path / "record.png")
    record_take(page, round(devices.seconds * 1000) + MARGIN_MS, screenshot)
    assert screenshot.read_bytes().startswith(PNG_SIGNATURE)
    assert recorder(page, "log.peakLevel") > 0.1  # the meter showed the clip's voice
    assert recorder(page, "state.current") == 1  # on to the sentence not yet recorded
    record_take(page, SHORT_TAKE_MS)
    assert recorder(page, "log.errors") == []
    uploads = recorder(page, "log.uploads")
    session = recorder(page, "state.session")
    stored = httpx.get(f"{served.http}/v1/recordings/{session}", trust_env=False).json()
    assert {take["index"]: take["bytes"] for take in stored["takes"]} == {
        upload["index"]: upload["bytes"] for upload in uploads
    }
    assert all(row_status(page, upload["index"])[1] == "uploaded" for upload in uploads)
    assert page.get_attribute("#upload", "value") == "1"

    page.click("#train")
    page.wait_for_function(
        "['done', 'failed'].includes(window.lipstreamRecord.state.job?.state)",
        timeout=TRAINING_MS,
    )
    job = recorder(page, "state.job")
    assert job["state"] == "done", job
    good, short = (upload["index"] for upload in uploads)
    assert row_status(page, good) == ("captured", "face and speech captured")
    failed = httpx.get(f"{served.http}/v1/recordings/{session}", trust_env=False).json()
    error = next(take for take in failed["takes"] if take["index"] == short)["error"]
    kind, text = row_status(page, short)
    assert kind == "failed" and error["message"] in text
    assert page.locator("#steps li.done").count() == page.locator("#steps li").count()
    assert float(page.eval_on_selector("#job-progress", "p => p.value")) == 1.0

    characters = httpx.get(f"{served.http}/v1/characters", trust_env=False).json()["characters"]
    engines = next(c["engines"] for c in characters if c["name"] == job["character"])
    page.click("#speak-link")
    page.wait_for_selector("body[data-ready=true]", timeout=WAIT_MS)
    assert page.url.endswith(f"/?character={job['character']}")
    assert page.input_value("#character") == job["character"]
    assert page.input_value("#engine") in engines
    page.evaluate(
        """() => {
            window.shapes = new Set();
            const mouth = document.getElementById("mouth-opening");
            const sample = () => {
                window.shapes.add(mouth.getAttribute("d"));
                requestAnimationFrame(sample);
            };
            sample();
        }"""
    )
    page.fill("#text", "Bin blue at f two now.")
    page.click("#speak")
    page.wait_for_function("window.lipstreamDemo.log.done.length === 1", timeout=WAIT_MS)
    done = page.evaluate("window.lipstreamDemo.log.done[0]")
    assert done["reason"] == "end" and done["stats"]["frames"] > 30
    page.wait_for_function(
        "document.getElementById('status').textContent === 'done'", timeout=WAIT_MS
    )
    assert page.evaluate("window.shapes.size") > 10  # the mouth took many shapes
    assert page.text_content("#errors") == ""
    page.context.close()


def test_refused_camera_permission_is_said_plainly(camera_browser: Any, served: LiveServer) -> None:
    page = record_page(camera_browser, served, [])
    page.click("#check")
    page.wait_for_function("window.lipstreamRecord.log.errors.length > 0", timeout=WAIT_MS)
    assert "permission to use the camera and microphone was denied" in page.inner_text("#errors")
    assert recorder(page, "state.stream") is None
    page.context.close()


def test_a_browser_without_media_recorder_is_told_so(
    camera_browser: Any, served: LiveServer
) -> None:
    context = camera_browser.new_context(permissions=GRANTED)
    context.add_init_script("delete window.MediaRecorder")
    page = context.new_page()
    page.goto(served.http + "/record")
    page.wait_for_selector("body[data-ready=true]", timeout=WAIT_MS)
    assert "cannot record video (it has no MediaRecorder)" in page.inner_text("#errors")
    context.close()


def test_a_taken_name_is_said_plainly(camera_browser: Any, served: LiveServer) -> None:
    characters = httpx.get(f"{served.http}/v1/characters", trust_env=False).json()["characters"]
    taken = characters[0]["name"]  # a character the server serves already
    page = record_page(camera_browser, served, GRANTED)
    page.fill("#name", taken)
    page.click("#create")
    page.wait_for_function("window.lipstreamRecord.log.errors.length > 0", timeout=WAIT_MS)
    assert f'the name "{taken}" is taken' in page.inner_text("#errors")
    assert recorder(page, "state.session") is None and page.is_enabled("#create")
    page.context.close()


def test_with_tokens_the_page_needs_one_and_passes_it_on(
    camera_browser: Any, guarded: LiveServer
) -> None:
    page = record_page(camera_browser, guarded, GRANTED)
    page.fill("#name", "no-token")
    page.click("#create")
    page.wait_for_function("window.lipstreamRecord.log.errors.length > 0", timeout=WAIT_MS)
    assert "unauthorized" in page.inner_text("#errors")
    page.context.close()

    page = record_page(camera_browser, guarded, GRANTED, f"?access_token={TOKEN}")
    start_session(page, "with-token", [TRANSCRIPT])
    links = page.eval_on_selector_all("a.keeps-token", "links => links.map(a => a.href)")
    assert links == [f"{guarded.http}/?access_token={TOKEN}"]
    page.context.close()


def test_a_take_over_the_limit_and_a_cut_connection_are_said_plainly(
    camera_browser: Any, guarded: LiveServer
) -> None:
    page = record_page(camera_browser, guarded, GRANTED, f"?access_token={TOKEN}")
    start_session(page, "too-big", [TRANSCRIPT])
    assert recorder(page, "state.limits.max_bytes") == SMALL_LIMIT
    record_take(page, 1000)
    assert "take 1 is too big" in page.inner_text("#errors")
    assert row_status(page, 0)[0] == "failed"
    status = httpx.get(
        f"{guarded.http}/v1/recordings/{recorder(page, 'state.session')}",
        headers={"authorization": f"Bearer {TOKEN}"},
        trust_env=False,
    ).json()
    assert status["takes"] == []  # the server kept nothing of it

    page.route("**/takes/**", lambda route: route.abort())
    record_take(page, 300)
    assert "the connection failed during the upload" in page.inner_text("#errors")
    assert "not uploaded" in row_status(page, 0)[1]
    page.context.close()
