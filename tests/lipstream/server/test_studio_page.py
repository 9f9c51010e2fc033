"""The studio page (/studio) in Debian's Chromium against a real server holding an
expressive-dp model: the map is drawn and a point previews a face, marking a node removes it
from the next synthesis, undo restores it, and pinning a constraint makes the search choose
the pinned node. Expectations come from the model and the contamination file, not the page."""

from __future__ import annotations

import json
import shutil
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from lipstream.engines.expressive_dp import ExpressiveDpModel
from lipstream.phonemes import PHONEMES
from tests.lipstream.server.browser import CHROMIUM, WAIT_MS, opened_page
from tests.live_server import LiveServer, live_server

pytestmark = pytest.mark.skipif(
    not CHROMIUM.exists() or shutil.which("espeak-ng") is None,
    reason="needs Debian's chromium and espeak-ng (README command (b) installs both)",
)
SENTENCE = "Maybe the bees bumped the map."


@pytest.fixture(scope="module")
def model(expressive_dp_model: ExpressiveDpModel) -> ExpressiveDpModel:
    return expressive_dp_model


@pytest.fixture(scope="module")
def served(expressive_dp_dir: Path) -> Iterator[LiveServer]:
    with live_server(expressive_dp_dir) as running:
        yield running


@pytest.fixture()
def page(browser: Any, served: LiveServer) -> Iterator[Any]:
    with opened_page(browser, served.http + "/studio", width=1500, height=1000) as page:
        yield page


def studio(page: Any, expression: str) -> Any:
    return page.evaluate(f"window.lipstreamStudio.{expression}")


def contaminated(served: LiveServer) -> list[int]:
    stored = served.models_dir / "expressive-dp" / "contamination.json"
    return list(json.loads(stored.read_text())["nodes"]) if stored.exists() else []


def test_the_map_is_drawn_and_a_point_previews_a_face(page: Any, model: ExpressiveDpModel) -> None:
    listed = page.locator("#phonemes tbody tr").count()
    assert listed == len(np.unique(model.nodes.phoneme))
    shown = studio(page, "state.phoneme")
    assert shown == next(
        PHONEMES[p] for p in np.unique(model.nodes.phoneme) if PHONEMES[p] != "sil"
    )
    inked = page.evaluate(
        """() => {
          const c = document.getElementById('map');
          const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
          let n = 0;
          for (let i = 0; i < d.length; i += 4) if (d[i] + d[i + 1] + d[i + 2] < 600) n++;
          return n;
        }"""
    )
    assert inked > 500  # kernels and trajectories, not a blank canvas
    rest = page.inner_html("#face")
    node = int(studio(page, "state.map.nodes[0].id"))
    point = studio(page, f"locate({node})")
    page.mouse.move(point["x"], point["y"])
    page.wait_for_function("window.lipstreamStudio.log.picks > 0", timeout=WAIT_MS)
    assert page.inner_html("#face") != rest  # the blend of a phoneme's frames is not at rest
    assert "nodes" in page.inner_text("#blend-info")


def synthesized(page: Any, count: int) -> list[int]:
    page.wait_for_function(f"window.lipstreamStudio.log.syntheses >= {count}", timeout=WAIT_MS)
    return [int(node) for node in studio(page, "log.paths.at(-1)")]


def test_marking_a_node_removes_it_and_pinning_a_node_makes_the_search_choose_it(
    page: Any, served: LiveServer, model: ExpressiveDpModel
) -> None:
    page.fill("#sentence", SENTENCE)
    page.click("#synthesize")
    first = synthesized(page, 1)
    items = studio(page, "state.sentence.items")
    assert len(first) == len(items)
    index = next(k for k, item in enumerate(items) if item["phoneme"] != "sil" and first[k] >= 0)
    page.click(f"#sentence-phonemes button[data-index='{index}']")
    page.wait_for_function(
        f"window.lipstreamStudio.state.sentenceIndex === {index} && "
        "window.lipstreamStudio.state.candidates !== null && "
        "window.lipstreamStudio.state.phoneme === window.lipstreamStudio.state.candidates.phoneme",
        timeout=WAIT_MS,
    )
    chosen = first[index]
    assert int(model.nodes.phoneme[chosen]) == PHONEMES.index(studio(page, "state.phoneme"))

    page.evaluate("document.getElementById('map').scrollIntoView({block: 'center'})")
    point = studio(page, f"locate({chosen})")  # in the viewport's coordinates: after scrolling
    page.mouse.click(point["x"], point["y"])
    page.wait_for_function("window.lipstreamStudio.log.clips > 0", timeout=WAIT_MS)
    if studio(page, "state.selectedNode") != chosen:  # another trajectory crosses it there
        page.evaluate(
            f"window.lipstreamStudio.state.selectedNode = {chosen};"
            "document.getElementById('mark-node').disabled = false"
        )
    page.click("#mark-node")
    avoided = synthesized(page, 2)
    assert contaminated(served) == [chosen]
    assert chosen not in avoided and avoided[index] != chosen

    page.click("#undo")
    restored = synthesized(page, 3)
    assert contaminated(served) == [] and restored == first

    members = [
        node
        for node in np.flatnonzero(model.nodes.phoneme == model.nodes.phoneme[chosen]).tolist()
        if node != chosen
    ]
    target = members[len(members) // 2]
    page.evaluate("document.getElementById('map').scrollIntoView({block: 'center'})")
    point = studio(page, f"locate({target})")
    page.mouse.click(point["x"], point["y"])
    page.wait_for_function("window.lipstreamStudio.log.clips > 1", timeout=WAIT_MS)
    selected = int(studio(page, "state.selectedNode"))
    assert int(model.nodes.phoneme[selected]) == int(model.nodes.phoneme[chosen])
    page.click("#pin")
    pinned = synthesized(page, 4)
    assert pinned[index] == selected
    assert json.loads(page.input_value("#export")) == {"constraints": {str(index): selected}}
    assert "not followed" not in page.inner_text("#constraints")
    assert studio(page, "log.errors") == []


def test_a_server_without_expressive_dp_says_so(browser: Any, lerp_dir: Path) -> None:
    with live_server(lerp_dir) as server, opened_page(browser, server.http + "/studio") as page:
        assert page.is_visible("#no-model") and not page.is_visible("#studio")
        assert "no expressive-dp model" in page.inner_text("#no-model")
