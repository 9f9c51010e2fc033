"""The docs hang together: every relative link in the README and docs/ reaches a file
that exists (and a heading there when it names one), every page is on the map
(docs/index.md), and the docs keep their four parts plus the reports."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.helpers import REPO

DOCS = REPO / "docs"
PAGES = sorted(DOCS.rglob("*.md"))
LINK = re.compile(r"\]\(([^)\s]+)\)")
FENCED = re.compile(r"^```.*?^```", re.DOTALL | re.MULTILINE)
HEADING = re.compile(r"^#+ (.*)$", re.MULTILINE)
PARTS = {"tutorials", "how-to", "reference", "explanation", "reports"}


def anchor(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces as hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def anchors(page: Path) -> set[str]:
    return {anchor(heading) for heading in HEADING.findall(FENCED.sub("", page.read_text()))}


def relative_links(page: Path) -> list[str]:
    text = FENCED.sub("", page.read_text(encoding="utf-8"))
    return [url for url in LINK.findall(text) if not re.match(r"^[a-z]+:", url) and url[0] != "/"]


def test_anchor_follows_github() -> None:
    assert anchor("Client → server messages") == "client--server-messages"
    assert anchor("`POST /v1/synthesize`") == "post-v1synthesize"
    assert anchor("Praat TextGrid: `<stem>.TextGrid`") == "praat-textgrid-stemtextgrid"


@pytest.mark.parametrize(
    "page", [REPO / "README.md", *PAGES], ids=lambda page: str(page.relative_to(REPO))
)
def test_relative_links_resolve(page: Path) -> None:
    broken = []
    for url in relative_links(page):
        path, _, heading = url.partition("#")
        target = (page.parent / path).resolve() if path else page
        if not target.exists():
            broken.append(f"{url}: no such file")
        elif heading and target.suffix == ".md" and heading not in anchors(target):
            broken.append(f"{url}: no such heading")
    assert not broken, broken


def test_every_page_is_in_a_part_and_on_the_map() -> None:
    index = DOCS / "index.md"
    linked = {(DOCS / url.partition("#")[0]).resolve() for url in relative_links(index)}
    for page in PAGES:
        if page == index:
            continue
        assert page.relative_to(DOCS).parts[0] in PARTS, page
        assert page.resolve() in linked, page


def test_readme_links_the_map() -> None:
    assert "](docs/index.md)" in (REPO / "README.md").read_text(encoding="utf-8")
