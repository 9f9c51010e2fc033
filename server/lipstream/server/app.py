"""The ASGI application: resident models in a typed lifespan state, REST and WebSocket routes.

Models load once when the process starts, and the ``Catalog`` measures and
probes them; ``/readyz`` turns ready only after that, and turns 503 again
while the process drains for shutdown, while ``/healthz`` answers as soon as
the process serves HTTP and keeps answering under load (engine work that
could stall the event loop runs in the synthesis thread pool, and the HTTP
protocol answers ``GET /healthz`` itself, before the app: ``handshake``).
The lifespan also starts the load monitor that admission follows
(``overload``), throttles repeated log lines (``log_throttle``) and logs
the limits in force. Routes:
``/healthz``, ``/readyz``, ``/v1/engines``, ``/v1/characters``, ``/v1/languages``,
``POST /v1/synthesize``, ``GET /metrics``, the WebSocket ``/v1/stream``, the
``expressive-dp`` phoneme-map and contamination routes (``phoneme_maps``) and
the recording routes ``/v1/recordings`` (``recordings``: a visitor's recordings
become a character, served without a restart), the OpenAPI docs (``/docs``, served
with its assets so it works offline, and ``/openapi.json``), the demo page ``/``
(``demo_page``) and the VRM page ``/vrm`` (``vrm_page``).
"""

from __future__ import annotations

import asyncio
import gc
import logging
import sys
from collections.abc import AsyncIterator, Callable, Hashable
from concurrent.futures import ThreadPoolExecutor
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any, TypedDict

from fastapi import FastAPI, Request, WebSocket
from fastapi.responses import JSONResponse, Response

from .._version import __version__
from ..config import ServerSettings, load_server_settings
from ..engines import ENGINES
from ..errors import LipstreamError
from ..frontends.espeak_languages import espeak_languages, espeak_variants
from ..models import ModelRegistry
from ..status import Heartbeat, Report, phase
from . import demo_page, docs_page, openapi, phoneme_maps, recordings, vrm_page
from .accept_gate import install_server_gate
from .catalog import Catalog
from .client_limits import ClientLimits
from .handshake import head_limits
from .held_input import InputLedger, input_budget_bytes
from .lanes import FairLane
from .lifecycle import Lifecycle, install_drain_on_signals
from .liveness import LivenessServer
from .load import MIB
from .log_throttle import install as throttle_repeated_log_lines
from .metrics import Metrics, forget_this_process
from .open_files import open_file_limit
from .overload import overload_for
from .rest import synthesize
from .startup import BUILDING, CALIBRATING, LOADING, READY, NotReady, Startup, run_in_background
from .state import ServerState
from .thread_priority import lower_this_thread
from .websocket import stream_endpoint

__all__ = ["LifespanState", "ServerState", "create_app"]

startup_log = logging.getLogger("uvicorn.error")


class LifespanState(TypedDict):
    startup: Startup


def _server(request: Request) -> ServerState:
    """The server state, or ``NotReady`` while the server starts up."""
    startup: Startup = request.state.startup
    return startup.serving()


async def _call(function: Callable[[ServerState], None], server: ServerState) -> None:
    function(server)


DRAINING = "draining"
NOT_READY_RETRY_S = 2
_frozen = False
GIL_SWITCH_INTERVAL_S = 0.0005
GC_YOUNG_OBJECTS = 20_000


def freeze_long_lived_objects() -> None:
    """Tune the serving process once: freeze its long-lived objects, collect the young
    generation less often, and shorten the GIL's switch interval.

    Called by the serving process after its models load: models, modules and the catalog
    live as long as the process, and a full collection that walks them takes 80 ms, a lag
    spike for every session. Objects made after the freeze (kernels loaded at a first
    call, connections, requests) still made full collections of 45-100 ms, a dozen a
    minute in a soak, each one a stall of every session and probe; the collector runs a
    full collection after every hundred young ones, so young collections every
    ``GC_YOUNG_OBJECTS`` tracked allocations instead of CPython's 700 make full ones about
    thirty times rarer, and a young one still takes about a millisecond. A pool thread
    running Python code (a PQ search, JSON encoding) hands the GIL to a waiting thread only
    every switch interval, and the event loop waits
    for it after every poll: at CPython's 5 ms that convoy lagged every session by seconds
    beside one large request; at 0.5 ms the loop gets the GIL back ten times sooner. An app
    built elsewhere (tests, embedding) leaves both alone."""
    global _frozen
    if not _frozen:
        _frozen = True
        gc.freeze()
        gc.set_threshold(GC_YOUNG_OBJECTS, *gc.get_threshold()[1:])
        sys.setswitchinterval(GIL_SWITCH_INTERVAL_S)


def create_app(
    models_path: Path,
    settings: ServerSettings | None = None,
    loaded: ModelRegistry | None = None,
    *,
    serving_process: bool = False,
    drain_flag: Path | None = None,
    prepare: Callable[[Report], ModelRegistry | None] | None = None,
    background: bool = False,
    on_failure: Callable[[], None] | None = None,
) -> FastAPI:
    """An app serving every model found under ``models_path`` (or the models already
    ``loaded`` from there) with ``settings`` (default: the ``LIPSTREAM_*`` environment).
    ``serving_process``: this process exists to serve the app, so its lifespan may change
    process-wide state (``freeze_long_lived_objects``). ``prepare`` runs first, in the
    phase ``building`` (``lipstream serve`` builds the demo character there, or checks the
    cached one), and returns the models under ``models_path`` when it loaded them. With
    ``background`` the lifespan returns at once, so the server listens while it starts up
    on a thread (``startup``); a failure then calls ``on_failure`` (the app's
    ``state.startup.failure`` says what failed). Without it the lifespan does the start-up
    itself and raises what fails. ``drain_flag``: the file whose existence says the
    workers' supervisor drains (``runner.DrainingSupervisor``)."""
    settings = settings or load_server_settings()
    metrics = Metrics()
    lifecycle = Lifecycle(settings.max_sessions, on_drain=lambda: metrics.draining.set(1))
    startup = Startup()

    @asynccontextmanager
    async def lifespan(_app: FastAPI) -> AsyncIterator[LifespanState]:
        throttle_repeated_log_lines()
        heartbeat = Heartbeat(startup.reporting(startup_log.info))
        report = heartbeat.report  # start-up steps, beside uvicorn's own start-up lines
        loop = asyncio.get_running_loop()
        running: list[Callable[[], None]] = []

        def start_up() -> ServerState:
            registry = loaded
            if prepare is not None:
                startup.enter(BUILDING)
                registry = prepare(report) or registry
            startup.enter(LOADING)
            if registry is None:
                with phase(f"loading the models in {models_path}", report):
                    registry = ModelRegistry.load(models_path, strict=settings.strict_models)
            startup.enter(CALIBRATING)
            catalog = Catalog.build(registry, settings, report)
            executor = ThreadPoolExecutor(
                settings.synth_threads,
                thread_name_prefix="lipstream-synth",
                initializer=lower_this_thread,
            )
            heavy = FairLane(
                settings.heavy_threads,
                "lipstream-heavy",
                _lane_waits(metrics, "heavy"),
                lower_this_thread,
            )
            speech = FairLane(
                settings.speech_threads,
                "lipstream-speech",
                _lane_waits(metrics, "speech"),
                lower_this_thread,
            )
            overload = overload_for(settings, catalog, metrics.observe_load)
            metrics.memory_ceiling.set(overload.policy.limits.max_memory_mb * MIB)
            ledger = InputLedger(
                input_budget_bytes(settings, overload.policy.limits.max_memory_mb),
                metrics.observe_input,
            )
            return ServerState(
                registry,
                catalog,
                settings,
                metrics,
                lifecycle,
                executor,
                heavy,
                speech,
                overload,
                ClientLimits.from_settings(settings),
                drain_flag=drain_flag,
                input_ledger=ledger,
            )

        def go_live(server: ServerState) -> None:
            """On the event loop: start what samples it, then turn ready."""
            heartbeat.stop()
            _log_limits(server)
            server.overload.monitor.start()
            running.append(server.overload.monitor.stop)
            running.append(install_server_gate(server))
            liveness = _liveness(settings, server.overload.monitor.last_tick)
            if liveness is not None:
                running.append(liveness.stop)
            if settings.recordings_enabled:
                running.append(recordings.watch(server))
            if serving_process:
                freeze_long_lived_objects()
            startup.ready(server)
            engines = sorted(server.catalog.engines)
            startup_log.info(
                "ready in %.1f s: %d model(s) of %s; GET /readyz answers 200",
                startup.clock() - startup.began,
                len(server.registry.models),
                ", ".join(engines),
            )

        def in_background() -> None:
            server = start_up()
            future = asyncio.run_coroutine_threadsafe(_call(go_live, server), loop)
            future.result()

        def failed() -> None:
            heartbeat.stop()
            startup_log.error("%s", startup.line)
            if on_failure is not None:
                loop.call_soon_threadsafe(on_failure)

        restore_signals = install_drain_on_signals(lifecycle, settings.drain_timeout_s)
        heartbeat.start()
        try:
            if background:
                run_in_background(in_background, startup, failed)
            else:
                go_live(start_up())
            yield {"startup": startup}
        finally:
            heartbeat.stop()
            for stop in reversed(running):
                stop()
            restore_signals()
            server = startup.server
            if server is not None:
                server.loaded = False
                server.executor.shutdown(wait=False, cancel_futures=True)
                server.heavy.shutdown(wait=False, cancel_futures=True)
                server.speech.shutdown(wait=False, cancel_futures=True)
            forget_this_process()

    app = FastAPI(
        title="lipstream",
        version=__version__,
        lifespan=lifespan,
        docs_url=None,
        redoc_url=None,
        description="Real-time lip sync: phoneme-aligned speech in, facial control "
        "frames out. Streaming is the WebSocket /v1/stream "
        "(docs/reference/protocol.md); this document covers the HTTP routes.",
    )
    app.state.lifecycle = lifecycle
    app.state.metrics = metrics
    app.state.startup = startup
    app.add_exception_handler(NotReady, _not_ready)
    openapi.install(app)
    docs_page.install(app, app.title)
    demo_page.install(app)
    vrm_page.install(app)

    @app.get("/healthz", summary="Liveness: the server answers", operation_id="healthz")
    async def healthz() -> dict[str, str]:
        return {"status": "ok"}

    @app.get("/readyz", summary="Readiness: the models are loaded", operation_id="readyz")
    async def readyz(request: Request) -> JSONResponse:
        """Ready or not: while starting up, the phase and its latest status line; then the
        model directories that are not served and why."""
        starting: Startup = request.state.startup
        server = starting.server
        if server is None:
            return JSONResponse(starting.report(), status_code=503)
        ready = server.ready
        detail = {
            "ready": ready,
            "phase": READY if ready else DRAINING,
            "failed_models": server.registry.failure_report(),
        }
        return JSONResponse(detail, status_code=200 if ready else 503)

    @app.get("/v1/engines", summary="List the engines", operation_id="list_engines")
    async def engines(request: Request) -> dict[str, Any]:
        loaded = {model.manifest.engine for model in _server(request).registry.models.values()}
        return {"engines": [{"name": name, "loaded": name in loaded} for name in ENGINES]}

    @app.get("/v1/characters", summary="List the characters", operation_id="list_characters")
    async def characters(request: Request) -> dict[str, Any]:
        registry = _server(request).registry
        return {
            "characters": [
                {"name": name, "engines": engines}
                for name, engines in registry.characters().items()
            ],
            "failed_models": registry.failure_report(),
        }

    @app.get("/v1/languages", summary="List espeak-ng's languages", operation_id="list_languages")
    async def languages() -> JSONResponse:
        """The languages a ``text`` may name (``lang``) and the voice variants (``voice``)."""
        try:
            listed = await asyncio.get_running_loop().run_in_executor(None, _languages)
        except LipstreamError as error:
            content = {"code": error.code, "message": error.message}
            return JSONResponse({"error": content}, status_code=503)
        return JSONResponse(listed)

    @app.post(
        "/v1/synthesize",
        summary="Synthesize a whole utterance",
        operation_id="synthesize",
        openapi_extra=openapi.synthesize_operation(),
        response_class=Response,
    )
    async def synthesize_route(request: Request) -> Response:
        """A whole utterance in, all its frames out (the frames /v1/stream would send)."""
        return await synthesize(request, _server(request))

    @app.get(
        "/metrics",
        summary="Prometheus metrics",
        operation_id="metrics",
        response_class=Response,
    )
    async def metrics_route(request: Request) -> Response:
        """Prometheus text exposition."""
        body, content_type = metrics.render()
        return Response(body, media_type=content_type)

    @app.websocket("/v1/stream")
    async def stream(websocket: WebSocket) -> None:
        await stream_endpoint(websocket)

    phoneme_maps.install(app)
    recordings.install(app)

    return app


def _languages() -> dict[str, Any]:
    """espeak-ng's languages and voice variants (read once per process)."""
    return {
        "languages": [
            {"lang": language.code, "name": language.title} for language in espeak_languages()
        ],
        "variants": list(espeak_variants()),
    }


def _lane_waits(metrics: Metrics, lane: str) -> Callable[[Hashable, int], None]:
    """Observe a job's wait in ``lane`` (``lipstream_lane_jobs_ahead``) by its source: a
    REST client (its key is ``("rest", address)``) or a WebSocket connection (``stream``)."""

    def observe(key: Hashable, ahead: int) -> None:
        source = key[0] if isinstance(key, tuple) and key else "stream"
        metrics.labelled(metrics.lane_jobs_ahead, lane, str(source)).observe(ahead)

    return observe


async def _not_ready(request: Request, error: Exception) -> Response:
    """503 ``starting`` with the phase, for a route called while the server starts up."""
    assert isinstance(error, NotReady)
    content = {"code": error.code, "message": error.message, "details": {"phase": error.where}}
    return JSONResponse(
        {"error": content}, status_code=503, headers={"Retry-After": str(NOT_READY_RETRY_S)}
    )


def _log_limits(server: ServerState) -> None:
    files = open_file_limit()
    _, connections = head_limits({"startup": Startup(server=server)})
    limits = server.overload.policy.limits
    startup_log.info(
        "limits: %d open files (hard limit %d), %d connections, %d sessions, "
        "%.0f MiB of memory (%.0f MiB of it for held audio input); admission refuses at "
        "%g ms of event-loop lag or %.0f %% busy (a session's calibrated cost: %.2f %% "
        "for the cheapest engine, %.2f %% for the dearest)",
        files.soft,
        files.hard,
        connections,
        server.settings.max_sessions,
        limits.max_memory_mb,
        server.input_ledger.budget_bytes / (1 << 20),
        limits.max_lag_ms,
        100 * limits.max_busy,
        100 * limits.session_cost,
        100 * max(limits.engine_costs.values(), default=limits.session_cost),
    )


def _liveness(settings: ServerSettings, last_tick: Callable[[], float]) -> LivenessServer | None:
    """The health port's server, started, when ``LIPSTREAM_HEALTH_PORT`` names one."""
    if not settings.health_port:
        return None
    try:
        liveness = LivenessServer(
            "0.0.0.0", settings.health_port, last_tick, settings.liveness_stall_s
        )
    except OSError as error:
        raise LipstreamError(
            f"cannot listen on the health port {settings.health_port}: {error}",
            where="LIPSTREAM_HEALTH_PORT",
            code="invalid_setting",
        ) from None
    liveness.start()
    return liveness
