"""``GET /``: the demo page, a face that speaks what you type, ``GET /studio``, the
phoneme-Isomap editor of ``expressive-dp``, and ``GET /record``, where a visitor records
their face and voice to make a character, served from package data.

Sketch: plain HTML, CSS and JavaScript modules in ``static/`` (no build step,
nothing loaded from elsewhere, so it works without internet). ``/`` is
``index.html``; ``/demo/<file>`` serves the page's other files, found by name
among the files the package ships, so no other path can be reached, and
``/favicon.ico`` is the page's icon (an SVG, as browsers ask that path first). The page
talks to the server only through the public protocol: ``GET /v1/engines`` and
``/v1/characters`` for its controls and the WebSocket ``/v1/stream`` (JSON
subprotocol, ``text`` and ``phonemes`` requests) for frames and speech. The studio
uses the phoneme-map routes (``phoneme_maps``) and ``POST /v1/synthesize``; the recording
page the recording routes (``/v1/recordings``), and links to ``/?character=<name>``, which
the demo page opens with that character chosen.
"""

from __future__ import annotations

from pathlib import Path

from fastapi import FastAPI, HTTPException
from fastapi.responses import FileResponse

STATIC_DIR = Path(__file__).resolve().parent / "static"
PAGE_URL = "/"
STUDIO_URL = "/studio"
RECORD_URL = "/record"
PAGES = ("index.html", "studio.html", "record.html")
ASSETS_URL = "/demo"
MEDIA_TYPES = {
    ".js": "text/javascript",
    ".css": "text/css",
    ".html": "text/html",
    ".svg": "image/svg+xml",
}
ICON = "favicon.svg"
ASSETS = {
    path.name: MEDIA_TYPES[path.suffix]
    for path in sorted(STATIC_DIR.iterdir())
    if path.suffix in MEDIA_TYPES and path.name not in PAGES
}


def install(app: FastAPI) -> None:
    """Add the demo page ``/``, the studio ``/studio``, the recording page ``/record`` and
    their files under ``/demo/`` to ``app``."""

    @app.get(PAGE_URL, include_in_schema=False)
    async def page() -> FileResponse:
        return FileResponse(STATIC_DIR / "index.html", media_type="text/html")

    @app.get(STUDIO_URL, include_in_schema=False)
    async def studio() -> FileResponse:
        return FileResponse(STATIC_DIR / "studio.html", media_type="text/html")

    @app.get(RECORD_URL, include_in_schema=False)
    async def record() -> FileResponse:
        return FileResponse(STATIC_DIR / "record.html", media_type="text/html")

    @app.get("/favicon.ico", include_in_schema=False)
    async def icon() -> FileResponse:
        return FileResponse(STATIC_DIR / ICON, media_type=MEDIA_TYPES[".svg"])

    @app.get(ASSETS_URL + "/{name}", include_in_schema=False)
    async def asset(name: str) -> FileResponse:
        media_type = ASSETS.get(name)
        if media_type is None:
            raise HTTPException(404, f"no demo page file {name!r}")
        return FileResponse(STATIC_DIR / name, media_type=media_type)
