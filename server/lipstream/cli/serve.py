"""``lipstream serve``: serve a model directory, or the demo character, built on first use.

With one worker the server listens first and starts up behind its port, so ``/healthz``
answers throughout and ``/readyz`` names the phase; with several workers or Ray the models
are built and loaded before serving, so every worker loads a set known to load."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from ..config import LOG_LEVELS, ServerSettings, Settings
from ..errors import LipstreamError
from .demo_cache import demo_ready

if TYPE_CHECKING:
    from ..models import ModelRegistry
    from ..status import Report
    from .commands import Commands

IMPORTING_THE_SERVER = "importing the server (numpy, scipy, numba, FastAPI, the engines)"


def _serve(args: argparse.Namespace, settings: Settings) -> None:
    from ..status import to_stderr

    host = args.host or settings.host
    port = settings.port if args.port is None else args.port
    server = settings.server.with_changes(
        workers=args.workers or settings.server.workers,
        log_level=args.log_level or settings.server.log_level,
        strict_models=args.strict_models or settings.server.strict_models,
    )
    models = Path(args.models) if args.models else settings.models
    build = args.models is None and not models.exists()
    check = args.models is None and models == settings.demo_models_dir
    if build:
        models = settings.demo_models_dir
    if args.ray or server.workers > 1:
        _serve_in_front(args, settings, models, server, build=build, check=check)
        return
    from ..server.front_door import FrontDoor, bind
    from ..server.open_files import raise_open_file_limit
    from ..status import Heartbeat, phase

    raise_open_file_limit()  # before the first connection is accepted, as serve() would
    door = FrontDoor(bind(host, port)).start()
    heartbeat = Heartbeat(_reporting_to(to_stderr, door.note)).start()
    heartbeat.report(
        f"lipstream serve: listening on http://{host}:{port} and starting up "
        "(GET /healthz answers now; GET /readyz names the phase until it is ready)"
    )
    try:
        with phase(IMPORTING_THE_SERVER, heartbeat.report):
            from ..server.runner import serve
    finally:
        heartbeat.stop()

    def prepare(report: Report) -> ModelRegistry | None:
        return demo_ready(settings, report, build=build, check=check)

    serve(
        models.resolve(),
        host,
        port,
        server,
        prepare=prepare if build or check else None,
        sock=door.hand_over(),
    )


def _reporting_to(*reports: Report) -> Report:
    def report(line: str) -> None:
        for each in reports:
            each(line)

    return report


def _serve_in_front(
    args: argparse.Namespace,
    settings: Settings,
    models: Path,
    server: ServerSettings,
    *,
    build: bool,
    check: bool,
) -> None:
    """Several workers or Ray: build and load before serving, so each worker (or replica)
    loads a model set known to load; a set that cannot be served stops here with one line."""
    from ..status import Heartbeat, phase, to_stderr

    heartbeat = Heartbeat(to_stderr).start()
    try:
        with phase(IMPORTING_THE_SERVER, heartbeat.report):
            from ..models import ModelRegistry
            from ..server.metrics import multiprocess_directory
            from ..server.runner import serve
        registry = demo_ready(settings, heartbeat.report, build=build, check=check)
        if registry is None:
            with phase(f"loading the models in {models.resolve()}", heartbeat.report):
                registry = ModelRegistry.load(models.resolve(), strict=server.strict_models)
    finally:
        heartbeat.stop()
    if args.ray:
        _serve_on_ray(args, settings, models.resolve(), server)
        return
    registry = None
    with multiprocess_directory(server.workers):
        serve(
            models.resolve(),
            args.host or settings.host,
            settings.port if args.port is None else args.port,
            server,
            registry,
        )


def _serve_on_ray(
    args: argparse.Namespace, settings: Settings, models: Path, server: ServerSettings
) -> None:
    try:
        from ..deploy.ray import serve_on_ray
    except ImportError as error:
        raise LipstreamError(
            f'--ray needs Ray Serve: pip install "lipstream[ray]" ({error})',
            where="--ray",
            code="missing_dependency",
        ) from None
    host = args.host or settings.host
    port = settings.port if args.port is None else args.port
    serve_on_ray(models, host, port, server, args.replicas)


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def add_serve_parser(commands: Commands) -> None:
    serve = commands.add_parser("serve", help="run the server")
    serve.add_argument(
        "--models",
        help="a model directory or a directory of them (default: $LIPSTREAM_MODELS, "
        "else the demo character, built on first use)",
    )
    serve.add_argument(
        "--host", help="interface to listen on (default: $LIPSTREAM_HOST or 127.0.0.1)"
    )
    serve.add_argument(
        "--port", type=int, help="TCP port to listen on (default: $LIPSTREAM_PORT or 8000)"
    )
    serve.add_argument(
        "--workers",
        type=_positive_int,
        help="worker processes sharing the memory-mapped models (default: $LIPSTREAM_WORKERS or 1)",
    )
    serve.add_argument(
        "--ray",
        action="store_true",
        help='serve on a local Ray Serve instance (pip install "lipstream[ray]")',
    )
    serve.add_argument(
        "--replicas",
        type=_positive_int,
        default=1,
        help="Ray Serve replicas with --ray, each loading the models once (default: 1)",
    )
    serve.add_argument(
        "--log-level",
        choices=LOG_LEVELS,
        help="uvicorn log level (default: $LIPSTREAM_LOG_LEVEL or info)",
    )
    serve.add_argument(
        "--strict-models",
        action="store_true",
        help="exit when any model fails to load (default: $LIPSTREAM_STRICT_MODELS or serve "
        "the others and report it)",
    )
    serve.set_defaults(run=_serve)
