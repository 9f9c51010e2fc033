"""The page's face (``static/face.js``) drawn alone in Debian's Chromium: each articulation
moves the parts it should, judged by the drawn geometry (``getBBox``) and by what the
browser paints at a point (``elementFromPoint``, which honours the mouth's clip path).

No server: the page and its files are answered from the package's ``static/`` directory
through Playwright's request routing, so only the face is under test.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest

from lipstream.server.demo_page import ASSETS, ASSETS_URL, STATIC_DIR
from tests.lipstream.server.browser import CHROMIUM, WAIT_MS

pytestmark = pytest.mark.skipif(not CHROMIUM.exists(), reason="needs Debian's chromium")

ORIGIN = "http://face.test"
PAGE = f"""<!doctype html><html><head><link rel="stylesheet" href="{ASSETS_URL}/demo.css">
</head><body data-ready="false"><svg id="face" style="width: 600px"></svg>
<script type="module">
import {{ Face }} from "{ASSETS_URL}/face.js";
window.face = new Face(document.getElementById("face"));
document.body.dataset.ready = "true";
</script></body></html>"""

# In page: draw `values`, then report each part's box and what is painted at SVG points.
DRAW = """([values, points]) => {
    const svg = document.getElementById("face");
    window.face.apply(values);
    const boxes = {};
    for (const node of svg.querySelectorAll("[id]")) {
        if (!node.getBBox) continue;
        const b = node.getBBox();
        boxes[node.id] = {x: b.x, y: b.y, width: b.width, height: b.height,
                          right: b.x + b.width, bottom: b.y + b.height};
    }
    const matrix = svg.getScreenCTM();
    const painted = points.map(([x, y]) => {
        const p = new DOMPoint(x, y).matrixTransform(matrix);
        const hit = document.elementFromPoint(p.x, p.y);
        return hit === null ? null : hit.id || hit.getAttribute("class");
    });
    return {boxes, painted};
}"""


@pytest.fixture(scope="module")
def page(browser: Any) -> Iterator[Any]:
    context = browser.new_context(viewport={"width": 700, "height": 800})
    page = context.new_page()

    def answer(route: Any) -> None:
        name = route.request.url.removeprefix(ORIGIN)
        if name == "/":
            route.fulfill(body=PAGE, content_type="text/html")
            return
        asset = name.removeprefix(ASSETS_URL + "/")
        route.fulfill(body=(STATIC_DIR / asset).read_bytes(), content_type=ASSETS[asset])

    page.route(ORIGIN + "/**", answer)
    page.goto(ORIGIN + "/")
    page.wait_for_selector("body[data-ready=true]", timeout=WAIT_MS)
    try:
        yield page
    finally:
        context.close()


def draw(
    page: Any, values: dict[str, float], points: tuple[tuple[float, float], ...] = ()
) -> tuple[dict[str, dict[str, float]], list[str | None]]:
    found = page.evaluate(DRAW, [values, [list(p) for p in points]])
    return found["boxes"], found["painted"]


def mouth_width(boxes: dict[str, dict[str, float]]) -> float:
    upper, lower = boxes["upper-lip"], boxes["lower-lip"]
    return max(upper["right"], lower["right"]) - min(upper["x"], lower["x"])


def test_the_neutral_face_shows_hair_ears_and_neck(page: Any) -> None:
    boxes, _ = draw(page, {})
    head = boxes["head"]
    # SVG points just outside the head: above its crown, beyond each side, below the chin.
    above = (head["x"] + head["width"] / 2, head["y"] - 4)
    beyond_left = (head["right"] + 4, head["y"] + 0.45 * head["height"])  # viewer's right
    beyond_right = (head["x"] - 4, head["y"] + 0.45 * head["height"])
    below = (head["x"] + head["width"] / 2, head["bottom"] + 5)
    _, painted = draw(page, {}, (above, beyond_left, beyond_right, below))
    assert painted[0] in {"hair", "fringe"}  # the fringe covers the crown, over the hair
    assert painted[1:] == ["ear-left", "ear-right", "neck"]
    assert boxes["hair"]["y"] < head["y"] and boxes["neck"]["bottom"] > head["bottom"]
    assert boxes["ear-left"]["x"] > head["x"] + head["width"] / 2 > boxes["ear-right"]["right"]


def test_the_open_jaw_hides_the_neck_it_showed(page: Any) -> None:
    rest, _ = draw(page, {})
    below = (rest["head"]["x"] + rest["head"]["width"] / 2, rest["head"]["bottom"] + 5)
    _, painted = draw(page, {"jawOpen": 0.5}, (below,))
    assert painted == ["head"]  # the chin fell over the point where the neck showed


def test_jaw_open_lowers_the_lower_teeth_with_the_chin_and_shows_the_tongue(page: Any) -> None:
    rest, _ = draw(page, {})
    opened, _ = draw(page, {"jawOpen": 0.5})
    chin_drop = opened["head"]["bottom"] - rest["head"]["bottom"]
    teeth_drop = opened["lower-teeth"]["y"] - rest["lower-teeth"]["y"]
    assert chin_drop > 10.0 and teeth_drop == pytest.approx(chin_drop, abs=0.05)

    def teeth_gap(boxes: dict[str, dict[str, float]]) -> float:
        return boxes["lower-teeth"]["y"] - boxes["teeth"]["bottom"]

    assert teeth_gap(opened) > teeth_gap(rest) + 10.0  # the rows part
    # Just above the lower teeth, in the middle, the page paints the tongue when the jaw is
    # open; at rest the lips cover that place.
    assert painted_above_lower_teeth(page, {"jawOpen": 0.5}) == "tongue"
    assert painted_above_lower_teeth(page, {}) in {"upper-lip", "lower-lip"}
    # The mouth's inside shows only between the lips: below the closed lips is the chin.
    lip = rest["lower-lip"]
    _, painted = draw(page, {}, ((lip["x"] + lip["width"] / 2, lip["bottom"] + 3.0),))
    assert painted == ["head"]


def painted_above_lower_teeth(page: Any, values: dict[str, float]) -> str | None:
    boxes, _ = draw(page, values)
    teeth = boxes["lower-teeth"]
    _, painted = draw(page, values, ((teeth["x"] + teeth["width"] / 2, teeth["y"] - 2.5),))
    return painted[0]


@pytest.mark.parametrize("narrowing", ["mouthFunnel", "mouthPucker"])
def test_funnel_and_pucker_narrow_the_mouth(page: Any, narrowing: str) -> None:
    rest, _ = draw(page, {"jawOpen": 0.2})
    rounded, _ = draw(page, {"jawOpen": 0.2, narrowing: 1.0})
    assert mouth_width(rounded) < 0.85 * mouth_width(rest)
    assert rounded["mouth-opening"]["width"] < 0.85 * rest["mouth-opening"]["width"]


def test_stretch_widens_the_mouth_on_its_own_side(page: Any) -> None:
    rest, _ = draw(page, {})
    both, _ = draw(page, {"mouthStretchLeft": 1.0, "mouthStretchRight": 1.0})
    left, _ = draw(page, {"mouthStretchLeft": 1.0})
    assert mouth_width(both) > 1.2 * mouth_width(rest)
    # The face's left is the viewer's right: only the right-hand corner moves out.
    assert left["upper-lip"]["right"] > rest["upper-lip"]["right"] + 3.0
    assert left["upper-lip"]["x"] == pytest.approx(rest["upper-lip"]["x"], abs=0.05)


@pytest.mark.parametrize("lip", ["upper", "lower"])
def test_rolling_a_lip_in_thins_it(page: Any, lip: str) -> None:
    rest, _ = draw(page, {})
    rolled, _ = draw(page, {f"mouthRoll{lip.title()}": 1.0})
    other = "lower" if lip == "upper" else "upper"
    assert rolled[f"{lip}-lip"]["height"] < 0.6 * rest[f"{lip}-lip"]["height"]
    assert rolled[f"{other}-lip"]["height"] == pytest.approx(rest[f"{other}-lip"]["height"])


def test_pressing_the_lips_narrows_the_opening(page: Any) -> None:
    opened, _ = draw(page, {"jawOpen": 0.4})
    pressed, _ = draw(page, {"jawOpen": 0.4, "mouthPressLeft": 1.0, "mouthPressRight": 1.0})
    assert pressed["mouth-opening"]["height"] < 0.8 * opened["mouth-opening"]["height"]
    assert pressed["mouth-opening"]["width"] < opened["mouth-opening"]["width"]
    assert pressed["upper-lip"]["height"] < opened["upper-lip"]["height"]


def test_the_face_returns_to_its_rest_drawing(page: Any) -> None:
    page.evaluate("window.face.apply({})")
    rest = page.inner_html("#face")
    page.evaluate("window.face.apply({jawOpen: 0.7, mouthFunnel: 1, eyeBlinkLeft: 1})")
    moved = page.inner_html("#face")
    page.evaluate("window.face.apply({})")
    assert moved != rest and page.inner_html("#face") == rest
