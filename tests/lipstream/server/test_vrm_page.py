"""The VRM page ``/vrm`` in headless Chromium against a real server: it loads a VRM built
by the test (``vrm_model``), speaks typed text with ``output.retarget``, and the model's
morph targets follow the frames that the test receives itself for the same request.

The avatar binds each expression to its own morph target with weight 1, so by the VRM
1.0 expression rule (influence = Σ bind weight × expression weight) each target's
influence must equal its expression's column of the served frames, to float32. Debian's
``chromium`` runs through Playwright (``test_demo_page`` has the launch flags).
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from lipstream.corpus.livelink import ARKIT_BLENDSHAPES
from tests.helpers import VRM1_EXPRESSIONS
from tests.lipstream.server.browser import CHROMIUM, WAIT_MS, opened_page
from tests.lipstream.server.vrm_model import FACE_MESH, UNBOUND_TARGET, build_vrm, glb
from tests.live_server import LiveServer, live_server

RIGS = {"vrm1": VRM1_EXPRESSIONS, "arkit52": tuple(ARKIT_BLENDSHAPES)}
MOUTH_OPENING = {"vrm1": "aa", "arkit52": "jawOpen"}
SENTENCE = "Hello there, how are you?"
ENGINE = "viseme-lerp"
FPS = 30

pytestmark = pytest.mark.skipif(
    not CHROMIUM.exists() or shutil.which("espeak-ng") is None,
    reason="needs Debian's chromium and espeak-ng (README command (b) installs both)",
)


@pytest.fixture(scope="module")
def served(lerp_dir: Path) -> Iterator[LiveServer]:
    with live_server(lerp_dir) as server:
        yield server


@pytest.fixture()
def page(browser: Any, served: LiveServer) -> Iterator[Any]:
    with opened_page(browser, served.http + "/vrm") as page:
        yield page


def load_model(page: Any, data: bytes) -> None:
    before = page.evaluate("window.lipstreamVrm.log.models + window.lipstreamVrm.log.errors.length")
    file = {"name": "avatar.vrm", "mimeType": "model/gltf-binary", "buffer": data}
    page.set_input_files("#model-file", files=[file])
    page.wait_for_function(
        f"window.lipstreamVrm.log.models + window.lipstreamVrm.log.errors.length > {before}",
        timeout=WAIT_MS,
    )


def served_frames(served: LiveServer, rig: str) -> tuple[list[str], np.ndarray]:
    """The test's own request, as the page sends it: (channels, frames as float32)."""
    from websockets.sync.client import connect
    from websockets.typing import Subprotocol

    rows: dict[int, list[float]] = {}
    with connect(served.ws, subprotocols=[Subprotocol("lipstream.v1.json")], proxy=None) as ws:
        for message in (
            {
                "type": "start",
                "id": "t",
                "engine": ENGINE,
                "character": "demo",
                "fps": FPS,
                "output": {"retarget": rig},
            },
            {"type": "text", "id": "t", "text": SENTENCE, "voice": "en-us", "rate": 160},
            {"type": "end", "id": "t"},
        ):
            ws.send(json.dumps({"v": 1, **message}))
        for _ in range(100_000):
            answer = json.loads(ws.recv(timeout=WAIT_MS / 1000))
            assert answer["type"] != "error", answer
            if answer["type"] == "ready":
                channels = answer["channels"]
            elif answer["type"] == "frames":
                for r, row in enumerate(answer["data"]):
                    rows[answer["first_frame"] + r] = row
            elif answer["type"] == "done":
                break
    assert sorted(rows) == list(range(answer["stats"]["frames"]))
    return channels, np.array([rows[i] for i in sorted(rows)], np.float32)


def speak(page: Any, rig: str) -> None:
    page.select_option("#engine", ENGINE)
    page.select_option("#retarget", rig)
    page.fill("#fps", str(FPS))
    page.fill("#text", SENTENCE)
    page.fill("#rate", "160")
    page.click("#speak")


def influences(page: Any, channels: list[str]) -> np.ndarray:
    """The face's morph target influences (columns in ``channels`` order, then ``unbound``)
    of every frame, each set through ``showAt`` at the frame's centre."""
    rows = page.evaluate(
        """([fps, names, mesh]) => {
            const rows = [];
            const count = window.lipstreamVrm.frames().length;
            for (let i = 0; i < count; i++) {
                window.lipstreamVrm.showAt((i + 0.5) / fps);
                const face = window.lipstreamVrm.morphInfluences()[mesh];
                rows.push(names.map((name) => face[name]));
            }
            return rows;
        }""",
        [FPS, [*channels, UNBOUND_TARGET], FACE_MESH],
    )
    return np.array(rows, np.float32)


@pytest.mark.parametrize("rig", sorted(RIGS))
def test_morph_targets_follow_the_served_frames(page: Any, served: LiveServer, rig: str) -> None:
    load_model(page, build_vrm(RIGS[rig]))
    assert page.evaluate("window.lipstreamVrm.log.errors") == []
    # Every animation frame during playback: the time the page played, the frame it
    # showed and what the face's morph targets were then.
    page.evaluate(
        """([mesh]) => {
            window.samples = [];
            const record = () => {
                const request = window.lipstreamVrm.request();
                if (request !== null && request.shown) {
                    const face = window.lipstreamVrm.morphInfluences()[mesh];
                    window.samples.push({...request.shown, influences: {...face}});
                }
                requestAnimationFrame(record);
            };
            record();
        }""",
        [FACE_MESH],
    )
    speak(page, rig)
    page.wait_for_function("window.lipstreamVrm.log.done.length === 1", timeout=WAIT_MS)
    channels, frames = served_frames(served, rig)
    page.wait_for_function(
        "document.getElementById('status').textContent === 'done'", timeout=WAIT_MS
    )
    samples = page.evaluate("window.samples")

    assert page.evaluate("window.lipstreamVrm.channels()") == channels
    if rig == "vrm1":
        assert sorted(channels) == sorted(VRM1_EXPRESSIONS)
    assert (
        page.text_content("#coverage")
        == f"{len(channels)} of {len(channels)} channels drive an expression"
    )
    np.testing.assert_array_equal(
        np.array(page.evaluate("window.lipstreamVrm.frames()"), np.float32), frames
    )
    assert frames[:, channels.index(MOUTH_OPENING[rig])].max() > 0.1  # the mouth opens

    shown = influences(page, channels)
    np.testing.assert_array_equal(shown[:, :-1], frames)
    assert not shown[:, -1].any()  # the target bound to no expression stays at rest

    columns = [*channels, UNBOUND_TARGET]
    played = {sample["frame"] for sample in samples}
    assert len(played) > 5  # the face changed with playback through the ~1.4 s sentence
    for sample in samples:
        assert 0 <= sample["frame"] <= sample["index"] == int(sample["t"] * FPS)
        row = np.array([sample["influences"][name] for name in columns], np.float32)
        np.testing.assert_array_equal(row, [*frames[sample["frame"]], 0.0])
    assert samples[-1]["frame"] == len(frames) - 1  # ends on the rest pose the server sends last
    assert page.evaluate("window.lipstreamVrm.request().sources.length") >= 1  # the speech played
    assert page.evaluate("window.lipstreamVrm.log.errors") == []


def test_a_gltf_without_vrm_is_refused_and_the_page_keeps_working(page: Any) -> None:
    plain = glb({"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": []}]}, b"")
    load_model(page, plain)
    assert page.evaluate("window.lipstreamVrm.log.errors") == [
        "cannot load the model: avatar.vrm: not a VRM (no VRMC_vrm or VRM extension)"
    ]
    assert page.is_disabled("#speak")
    load_model(page, build_vrm(VRM1_EXPRESSIONS))
    assert page.is_enabled("#speak")
    assert page.text_content("#status") == "loaded lipstream test avatar: 12 expressions"


def test_the_page_loads_only_from_the_server_and_serves_the_licences(
    page: Any, served: LiveServer
) -> None:
    import httpx

    assert page.requested and all(url.startswith(served.http) for url in page.requested)
    loaded = {url.removeprefix(served.http) for url in page.requested}
    assert "/vrm/vendor/three-vrm/three-vrm.module.min.js" in loaded
    assert "/vrm/vendor/three/three.module.js" in loaded
    for licence in ("/vrm/vendor/three/LICENSE", "/vrm/vendor/three-vrm/LICENSE"):
        answer = httpx.get(served.http + licence, trust_env=False)
        assert answer.status_code == 200 and answer.headers["content-type"].startswith("text/plain")
        assert "The MIT License" in answer.text or "MIT License" in answer.text
    for path in ("/vrm/index.html", "/vrm/../demo.js", "/vrm/vendor/three/package.json"):
        assert httpx.get(served.http + path, trust_env=False).status_code == 404


def test_a_model_url_in_the_query_is_loaded(browser: Any, served: LiveServer) -> None:
    context = browser.new_context()
    page = context.new_page()
    # The test's avatar, answered by the browser itself at a URL the server does not have.
    page.route(
        served.http + "/avatars/test.vrm",
        lambda route: route.fulfill(
            body=build_vrm(VRM1_EXPRESSIONS), content_type="model/gltf-binary"
        ),
    )
    page.goto(served.http + "/vrm?model=/avatars/test.vrm")
    page.wait_for_function("window.lipstreamVrm.log.models === 1", timeout=WAIT_MS)
    assert page.input_value("#model-url") == "/avatars/test.vrm"
    assert page.evaluate("Object.keys(window.lipstreamVrm.expressionWeights()).sort()") == sorted(
        VRM1_EXPRESSIONS
    )
    context.close()
