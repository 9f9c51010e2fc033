"""``/docs`` works offline: every script, stylesheet and icon it loads comes from the server."""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path
from urllib.parse import urljoin, urlparse

import httpx
import pytest

from tests.live_server import LiveServer, live_server

REFERENCE = re.compile(r"""<(?:script|link)\b[^>]*?\b(?:src|href)\s*=\s*["']([^"']+)["']""", re.I)


@pytest.fixture(scope="module")
def served(lerp_dir: Path) -> Iterator[LiveServer]:
    with live_server(lerp_dir) as server:
        yield server


def references(page: str) -> list[str]:
    """The URLs of every ``<script src>`` and ``<link href>`` of ``page``."""
    return REFERENCE.findall(page)


def test_reference_finder_sees_cdn_urls() -> None:
    page = (
        '<link type="text/css" rel="stylesheet" href="https://cdn.example/ui.css">\n'
        '<script src="https://cdn.example/ui.js"></script><script>inline()</script>'
    )
    assert references(page) == ["https://cdn.example/ui.css", "https://cdn.example/ui.js"]


def test_docs_page_loads_only_assets_the_server_serves(served: LiveServer) -> None:
    with httpx.Client(base_url=served.http, trust_env=False, timeout=10.0) as client:
        page = client.get("/docs")
        assert page.status_code == 200 and "text/html" in page.headers["content-type"]
        urls = references(page.text)
        kinds = {urlparse(url).path.rsplit(".", 1)[-1] for url in urls}
        assert {"js", "css"} <= kinds, urls
        for url in urls:
            absolute = urljoin(served.http + "/docs", url)
            assert urlparse(absolute).netloc == urlparse(served.http).netloc, url
            asset = client.get(absolute)
            assert asset.status_code == 200, url
            assert asset.content, url
        bundle = client.get("/docs/assets/swagger-ui-bundle.js")
        assert "SwaggerUIBundle" in bundle.text[:2000]
        assert "javascript" in bundle.headers["content-type"]
        assert client.get("/openapi.json").json()["openapi"].startswith("3.")
        assert client.get("/docs/assets/index.html").status_code == 404
        assert client.get("/docs/assets/..%2F__init__.py").status_code == 404
