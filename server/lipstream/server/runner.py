"""Running the app under uvicorn: one configuration for the CLI, the workers and the tests.

Sketch: per-message deflate is off (it doubles memory per connection and
invites decompression bombs), the WebSocket frame limit is twice the
protocol's message limit (so a message between the two gets a
``message_too_large`` error before the 1009 close, and anything larger is
cut off by the WebSocket layer itself), the WebSocket and HTTP protocols are
uvicorn's own with a bound on how long a client that stops reading may hold
its socket (``closing.BoundedCloseProtocol``,
``http_flush.BoundedFlushHTTPProtocol``), and uvicorn's ``limit_concurrency``
stays unset: it does not cap WebSockets and would make plain HTTP answer 503
while sessions are open; the app keeps its own session cap. With one worker
the app object is served directly; with ``--workers N`` uvicorn's supervisor
starts N processes, each building the app from the environment
(``app_from_environment``), and each maps the same model files, so their
pages are shared.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import uvicorn
from fastapi import FastAPI

from ..config import ServerSettings, load_settings
from ..models import ModelRegistry
from .app import create_app
from .closing import BoundedCloseProtocol
from .http_flush import BoundedFlushHTTPProtocol

APP_FACTORY = "lipstream.server.runner:app_from_environment"
GRACEFUL_EXIT_S = 5.0


def app_from_environment() -> FastAPI:
    """The app for ``LIPSTREAM_MODELS`` and the ``LIPSTREAM_*`` settings (worker entry)."""
    settings = load_settings()
    return create_app(settings.models, settings.server)


def uvicorn_options(server: ServerSettings) -> dict[str, Any]:
    """Keyword arguments for ``uvicorn.Config`` that every way of serving shares."""
    return {
        "log_level": server.log_level,
        "http": BoundedFlushHTTPProtocol,
        "ws": BoundedCloseProtocol,
        "ws_max_size": 2 * server.max_message_bytes,
        "ws_per_message_deflate": False,
        "ws_ping_interval": server.ping_interval_s,
        "ws_ping_timeout": server.ping_timeout_s,
        "timeout_graceful_shutdown": GRACEFUL_EXIT_S,
        "lifespan": "on",
    }


def serve(
    models: Path,
    host: str,
    port: int,
    server: ServerSettings,
    registry: ModelRegistry | None = None,
) -> None:
    """Serve ``models`` (already loaded as ``registry``, for one worker) until SIGTERM or
    SIGINT, draining first (see ``lifecycle``)."""
    if server.workers > 1:
        os.environ["LIPSTREAM_MODELS"] = str(models)
        uvicorn.run(
            APP_FACTORY,
            factory=True,
            host=host,
            port=port,
            workers=server.workers,
            **uvicorn_options(server),
        )
        return
    config = uvicorn.Config(
        create_app(models, server, registry), host=host, port=port, **uvicorn_options(server)
    )
    uvicorn.Server(config).run()
