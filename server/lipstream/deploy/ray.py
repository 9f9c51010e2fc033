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

Drain: Serve tells the app nothing when it begins to stop a replica (scaling
down, a redeploy, ``serve.delete``, ``serve.shutdown``): the replica gets no
signal, and the app's lifespan ends only after Serve's own wait for the
replica's requests, which a WebSocket keeps ongoing for its whole life.
``drain_when_serve_stops`` therefore wraps the replica's shutdown step
(``Replica._perform_graceful_shutdown`` of the pinned Ray release, checked at
import) in the replica's process, so that it first starts the server's own
drain (``Lifecycle.drain``, as SIGTERM does under ``lipstream serve``) on the
app's event loop, which ``LifespanStateBridge`` notes when the lifespan
starts. New ``start``s are refused with ``shutting_down`` from that moment,
each connection closes with 1001 once its requests are done, the rest are
closed with 1001 at the drain timeout, and Serve's wait, which then finds no
request ongoing, goes on as before.
``serve_on_ray`` starts a local Ray instance and runs the application behind
Ray's HTTP proxy until SIGINT or SIGTERM; it deletes the application first
(the replicas drain while the proxy still carries their connections), then
shuts Serve down.
"""

from __future__ import annotations

import asyncio
import functools
import inspect
import logging
import signal
import threading
from collections.abc import Awaitable, Callable
from concurrent.futures import Future
from pathlib import Path
from typing import Any

from fastapi import FastAPI
from ray import serve
from ray.serve import Application
from ray.serve._private.replica import Replica
from starlette.types import ASGIApp, Receive, Scope, Send

from ..config import ServerSettings
from ..server.app import create_app
from ..server.lifecycle import Lifecycle

logger = logging.getLogger("lipstream.server")

HTTP_ROOM = 32
"""Ongoing-request slots beyond the session cap, for the HTTP routes (/readyz, /metrics...)."""
SHUTDOWN_MARGIN_S = 30.0
DEPLOYMENT_NAME = "lipstream"
APPLICATION_NAME = "lipstream"
SHUTDOWN_STEP = "_perform_graceful_shutdown"
"""The replica's shutdown step that ``drain_when_serve_stops`` wraps (Ray's private API:
the ``ray`` extra pins the release it was read from)."""
if not inspect.iscoroutinefunction(getattr(Replica, SHUTDOWN_STEP, None)):
    raise ImportError(
        f"this Ray release has no coroutine Replica.{SHUTDOWN_STEP}, which lipstream wraps "
        'to drain a stopping replica: install the release the "ray" extra pins'
    )


class LifespanStateBridge:
    """An ASGI app that passes the lifespan's state into every request's scope (as uvicorn
    does, and Ray Serve's replica wrapper does not)."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app
        self.state: dict[str, Any] = {}
        self.loop: asyncio.AbstractEventLoop | None = None
        """The loop the app runs on (the lifespan's), once its lifespan started."""

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "lifespan":
            self.state = scope.setdefault("state", {})
            self.loop = asyncio.get_running_loop()
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


ShutdownStep = Callable[[Replica], Awaitable[None]]


def drain_when_serve_stops(
    bridge: LifespanStateBridge, lifecycle: Lifecycle, timeout_s: float
) -> None:
    """In this replica's process: when Serve begins to stop the replica, start the server's
    drain (``timeout_s``) on the app's loop, then go on with Serve's shutdown, whose wait
    for ongoing requests ends when the drain has closed the connections."""
    step: ShutdownStep = getattr(Replica, SHUTDOWN_STEP)
    original: ShutdownStep = getattr(step, "__wrapped__", step)
    drains: list[Future[int]] = []

    @functools.wraps(original)
    async def drain_then_stop(replica: Replica) -> None:
        if bridge.loop is not None and not lifecycle.draining:
            drain = asyncio.run_coroutine_threadsafe(lifecycle.drain(timeout_s), bridge.loop)
            drains.append(drain)  # kept: the loop holds only a weak reference to the task
            logger.info("Serve is stopping this replica: draining for up to %g s", timeout_s)
        await original(replica)

    setattr(Replica, SHUTDOWN_STEP, drain_then_stop)


def build_app(models: Path, settings: ServerSettings, replicas: int) -> Application:
    """The Serve application: ``replicas`` replicas of the app serving ``models``, each of
    which drains as ``lipstream serve`` does when Serve stops it."""
    models = models.resolve()

    def app_on_replica() -> LifespanStateBridge:
        app: FastAPI = create_app(models, settings)
        bridge = LifespanStateBridge(app)
        drain_when_serve_stops(bridge, app.state.lifecycle, settings.drain_timeout_s)
        return bridge

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
    HTTP proxy on ``host``:``port``, and block until SIGINT or SIGTERM; then delete the
    application (each replica drains, its connections still carried by the proxy) and shut
    Serve down."""
    import ray

    ray.init(include_dashboard=False, configure_logging=False)
    try:
        serve.start(http_options={"host": host, "port": port})
        application = build_app(models, settings, replicas)
        serve.run(application, name=APPLICATION_NAME, route_prefix="/")
        stop = threading.Event()
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, lambda *_: stop.set())
        stop.wait()
        serve.delete(APPLICATION_NAME)
        serve.shutdown()  # type: ignore[no-untyped-call, unused-ignore]
    finally:
        ray.shutdown()
