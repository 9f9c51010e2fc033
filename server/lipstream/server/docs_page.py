"""``GET /docs``: Swagger UI served by the server itself, so the page works offline.

Sketch: FastAPI's own docs page loads Swagger UI's script and stylesheet from a
CDN, which leaves it blank without network. Here the page is FastAPI's
``get_swagger_ui_html`` pointed at ``/docs/assets/<file>``, and those files
come from the ``swagger-ui-bundle-v2`` package (Swagger UI 5, which renders the
OpenAPI 3.1 that FastAPI writes). Only the three files the page needs are
served, by name, so no other path under the package can be reached.
"""

from __future__ import annotations

from fastapi import FastAPI, HTTPException
from fastapi.openapi.docs import get_swagger_ui_html
from fastapi.responses import FileResponse, HTMLResponse
from swagger_ui_bundle import swagger_ui_path

DOCS_URL = "/docs"
ASSETS_URL = "/docs/assets"
ASSETS = {
    "swagger-ui-bundle.js": "text/javascript",
    "swagger-ui.css": "text/css",
    "favicon-32x32.png": "image/png",
}


def install(app: FastAPI, title: str) -> None:
    """Add ``/docs`` and its assets to ``app`` (created with ``docs_url=None``)."""

    @app.get(DOCS_URL, include_in_schema=False)
    async def docs() -> HTMLResponse:
        return get_swagger_ui_html(
            openapi_url=app.openapi_url or "/openapi.json",
            title=f"{title} - API documentation",
            swagger_js_url=f"{ASSETS_URL}/swagger-ui-bundle.js",
            swagger_css_url=f"{ASSETS_URL}/swagger-ui.css",
            swagger_favicon_url=f"{ASSETS_URL}/favicon-32x32.png",
        )

    @app.get(ASSETS_URL + "/{name}", include_in_schema=False)
    async def asset(name: str) -> FileResponse:
        media_type = ASSETS.get(name)
        if media_type is None:
            raise HTTPException(404, f"no docs asset {name!r}")
        return FileResponse(swagger_ui_path / name, media_type=media_type)
