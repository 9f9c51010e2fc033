"""``GET /vrm``: a three.js page that makes a VRM avatar speak what you type, from package data.

Sketch: like the demo page, plain HTML and JavaScript modules with no build step and
nothing loaded from elsewhere. ``static/vrm/`` holds the page and, under ``vendor/``,
the ES modules of ``three`` and ``@pixiv/three-vrm`` copied unchanged from npm with
their licences (``vendor/NOTICE.txt``); the page's import map points the bare names
``three`` and ``@pixiv/three-vrm`` at them. ``/vrm/<path>`` serves only the files the
package ships under ``static/vrm/``, listed once at import, so no other path can be
reached. The page shares the demo page's stylesheet and its ``stream.js`` (the protocol,
the clock, the controls) from ``/demo/``, and talks to the server through the public
protocol only: ``GET /v1/engines`` and ``/v1/characters``, and ``/v1/stream`` (JSON
subprotocol, ``text`` requests with ``output.retarget``).
"""

from __future__ import annotations

from pathlib import Path

from fastapi import FastAPI, HTTPException
from fastapi.responses import FileResponse

from .demo_page import MEDIA_TYPES, STATIC_DIR

VRM_DIR = STATIC_DIR / "vrm"
PAGE_URL = "/vrm"
TEXT_FILES = {"LICENSE": "text/plain", "NOTICE.txt": "text/plain"}


def _media_type(path: Path) -> str | None:
    return TEXT_FILES.get(path.name) or MEDIA_TYPES.get(path.suffix)


FILES = {
    path.relative_to(VRM_DIR).as_posix(): media_type
    for path in sorted(VRM_DIR.rglob("*"))
    if path.is_file() and path.name != "index.html" and (media_type := _media_type(path))
}


def install(app: FastAPI) -> None:
    """Add the VRM page ``/vrm`` and its files under ``/vrm/`` to ``app``."""

    @app.get(PAGE_URL, include_in_schema=False)
    async def page() -> FileResponse:
        return FileResponse(VRM_DIR / "index.html", media_type="text/html")

    @app.get(PAGE_URL + "/{path:path}", include_in_schema=False)
    async def asset(path: str) -> FileResponse:
        media_type = FILES.get(path)
        if media_type is None:
            raise HTTPException(404, f"no VRM page file {path!r}")
        return FileResponse(VRM_DIR / path, media_type=media_type)
