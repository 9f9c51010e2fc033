"""lipstream on Ray Serve: the server's own FastAPI app as the ingress of a Serve deployment.

Method: ``build_app`` returns a Serve application whose deployment wraps the
app that ``lipstream serve`` runs (``create_app``), built on each replica when
it starts (a builder function, so the models are loaded by the replica's own
lifespan, once per replica, and nothing large is pickled). Ray runs the
app's lifespan with uvicorn's lifespan code but does not hand the lifespan's
state to the requests, as uvicorn does; ``LifespanStateBridge`` keeps that
state and copies it into every HTTP and WebSocket scope. A WebSocket holds
one ongoing-request slot of its replica for its whole life, so
``max_ongoing_requests`` is the session cap plus room for the HTTP routes,
leaving admission to the server (``server_busy``); and
``graceful_shutdown_timeout_s`` is the drain timeout plus a margin, so the
utterances in flight when Serve stops a replica finish first.
``serve_on_ray`` starts a local Ray instance and runs the application behind
Ray's HTTP proxy until SIGINT or SIGTERM.
"""

from __future__ import annotations

import signal
import threading
from pathlib import Path
from typing import Any

from ray import serve
from ray.serve import Application
from starlette.types import ASGIApp, Receive, Scope, Send

from ..config import ServerSettings
from ..server.app import create_app

HTTP_ROOM = 32
"""Ongoing-request slots beyond the session cap, for the HTTP routes (/readyz, /metrics...)."""
SHUTDOWN_MARGIN_S = 30.0
DEPLOYMENT_NAME = "lipstream"


class LifespanStateBridge:
    """An ASGI app that passes the lifespan's state into every request's scope (as uvicorn
    does, and Ray Serve's replica wrapper does not)."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app
        self.state: dict[str, Any] = {}

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "lifespan":
            self.state = scope.setdefault("state", {})
        else:
            scope["state"] = {**self.state, **scope.get("state", {})}
        await self.app(scope, receive, send)


def max_ongoing_requests(settings: ServerSettings) -> int:
    """A replica's slots: one per session it may hold, and room for the HTTP routes."""
    return settings.max_sessions + HTTP_ROOM


def graceful_shutdown_timeout_s(settings: ServerSettings) -> float:
    """How long Serve lets a stopping replica serve its connections: the drain timeout
    (above the longest utterance) and a margin."""
    return settings.drain_timeout_s + SHUTDOWN_MARGIN_S


def build_app(models: Path, settings: ServerSettings, replicas: int) -> Application:
    """The Serve application: ``replicas`` replicas of the app serving ``models``."""
    models = models.resolve()

    def app_on_replica() -> LifespanStateBridge:
        return LifespanStateBridge(create_app(models, settings))

    ingress = serve.ingress(app_on_replica)(type("LipstreamIngress", (), {}))
    deployment = serve.deployment(
        name=DEPLOYMENT_NAME,
        num_replicas=replicas,
        max_ongoing_requests=max_ongoing_requests(settings),
        graceful_shutdown_timeout_s=graceful_shutdown_timeout_s(settings),
    )(ingress)
    application: Application = deployment.bind()
    return application


def serve_on_ray(
    models: Path, host: str, port: int, settings: ServerSettings, replicas: int
) -> None:
    """Start a local Ray instance, serve ``models`` on ``replicas`` replicas behind Ray's
    HTTP proxy on ``host``:``port``, and block until SIGINT or SIGTERM; then shut Serve
    down (each replica drains within its graceful shutdown timeout)."""
    import ray

    ray.init(include_dashboard=False, configure_logging=False)
    try:
        serve.start(http_options={"host": host, "port": port})
        serve.run(build_app(models, settings, replicas), name="lipstream", route_prefix="/")
        stop = threading.Event()
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, lambda *_: stop.set())
        stop.wait()
        serve.shutdown()  # type: ignore[no-untyped-call, unused-ignore]
    finally:
        ray.shutdown()
