"""Running the app under uvicorn: one configuration for the CLI, the workers and the tests.

Sketch: per-message deflate is off (it doubles memory per connection and
invites decompression bombs), the WebSocket frame limit is twice the
protocol's message limit (so a message between the two gets a
``message_too_large`` error before the 1009 close, and anything larger is
cut off by the WebSocket layer itself), the WebSocket and HTTP protocols are
uvicorn's own with a bound on how long a client that stops reading may hold
its socket (``closing.BoundedCloseProtocol``, which also reads up to a window of
messages ahead of the app instead of pausing its socket after each, ``read_window``;
``http_flush.BoundedFlushHTTPProtocol``), the HTTP one also with a deadline
for the request head and a cap on open connections
(``handshake.GuardedHTTPProtocol``), and uvicorn's ``limit_concurrency``
stays unset: it does not cap WebSockets and would make plain HTTP answer 503
while sessions are open; the app keeps its own session cap. Before uvicorn
starts, the soft open-file limit is raised as far as the hard one allows
(``open_files``); the workers inherit it. With one worker
the app object is served directly; with ``--workers N`` uvicorn's supervisor
starts N processes, each building the app from the environment
(``app_from_environment``), and each maps the same model files, so their
pages are shared. The serving process's models path and settings reach the
workers whole, as JSON in one private variable (``WORKER_APP_ENV``) that is
set only while uvicorn runs, so serving leaves ``os.environ`` as it found it.
Either way the app is told it owns its process (``serving_process``), so it
freezes the collector's view of its models once they load, and the event loop is
``accept_loop.BoundedAcceptLoop``, which takes a bounded number of new connections per
turn.

With several workers, SIGTERM reaches the supervisor, which uvicorn's loop looks at only
every half second before it signals the workers: until then each worker's ``/readyz``
would still say ready. So the supervisor (``DrainingSupervisor``) marks the drain in
state the workers share, a file in a private directory named in ``WORKER_APP_ENV``, from
its signal handler, before uvicorn's loop sees the signal; a worker's ``/readyz`` answers
503 from then on (``ServerState.ready``).
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import signal
import socket
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import asdict
from pathlib import Path
from types import FrameType
from typing import Any

import uvicorn
from fastapi import FastAPI
from uvicorn.supervisors import Multiprocess

from ..config import ServerSettings, load_settings
from ..models import ModelRegistry
from ..status import Report
from .accept_loop import LOOP as ACCEPT_LOOP
from .app import create_app
from .closing import BoundedCloseProtocol
from .front_door import BACKLOG
from .handshake import GuardedHTTPProtocol
from .lifecycle import DRAIN_SIGNALS
from .open_files import raise_open_file_limit

logger = logging.getLogger("uvicorn.error")

APP_FACTORY = "lipstream.server.runner:app_from_environment"
WORKER_APP_ENV = "LIPSTREAM_WORKER_APP"
GRACEFUL_EXIT_S = 5.0
WORKER_HEALTHCHECK_S = 30
DRAIN_FLAG = "draining"
DRAIN_MARKED = "draining: /readyz answers 503 from now on"


class DrainingSupervisor(Multiprocess):
    """uvicorn's supervisor of worker processes, which marks the drain in ``drain_flag`` as
    soon as a drain signal arrives."""

    def __init__(self, config: uvicorn.Config, sockets: list[socket.socket], drain_flag: Path):
        super().__init__(config, sockets)
        self.drain_flag = drain_flag
        for sig in DRAIN_SIGNALS:
            signal.signal(sig, self.on_drain_signal)

    def on_drain_signal(self, sig: int, frame: FrameType | None) -> None:
        if not self.drain_flag.exists():
            self.drain_flag.touch()
            logger.warning(DRAIN_MARKED)
        self.signal_queue.append(sig)


def encode_worker_app(models: Path, server: ServerSettings, drain_flag: Path | None = None) -> str:
    """The models path and settings of the serving process, and where its supervisor marks
    the drain, for its workers."""
    fields = asdict(server)
    fields["profiles"] = None if server.profiles is None else str(server.profiles)
    fields["recordings_dir"] = None if server.recordings_dir is None else str(server.recordings_dir)
    flag = None if drain_flag is None else str(drain_flag)
    return json.dumps({"models": str(models), "server": fields, "drain_flag": flag})


def worker_drain_flag(text: str) -> Path | None:
    """Where the supervisor of the workers ``text`` describes marks the drain."""
    flag = json.loads(text).get("drain_flag")
    return None if flag is None else Path(flag)


def decode_worker_app(text: str) -> tuple[Path, ServerSettings]:
    """The inverse of ``encode_worker_app``."""
    document = json.loads(text)
    fields = document["server"]
    fields["auth_tokens"] = tuple(fields["auth_tokens"])
    fields["allowed_origins"] = tuple(fields["allowed_origins"])
    fields["profiles"] = None if fields["profiles"] is None else Path(fields["profiles"])
    recordings = fields["recordings_dir"]
    fields["recordings_dir"] = None if recordings is None else Path(recordings)
    return Path(document["models"]), ServerSettings(**fields)


def app_from_environment() -> FastAPI:
    """The worker entry: the app ``serve`` described in ``WORKER_APP_ENV``, else the one for
    ``LIPSTREAM_MODELS`` and the ``LIPSTREAM_*`` settings."""
    described = os.environ.get(WORKER_APP_ENV)
    if described:
        models, server = decode_worker_app(described)
        flag = worker_drain_flag(described)
        return create_app(models, server, serving_process=True, drain_flag=flag)
    settings = load_settings()
    return create_app(settings.models, settings.server, serving_process=True)


@contextmanager
def exported(name: str, value: str) -> Iterator[None]:
    """``os.environ[name] = value`` for the block (children started in it inherit it), then
    the variable as it was."""
    before = os.environ.get(name)
    os.environ[name] = value
    try:
        yield
    finally:
        if before is None:
            os.environ.pop(name, None)
        else:
            os.environ[name] = before


def uvicorn_options(server: ServerSettings) -> dict[str, Any]:
    """Keyword arguments for ``uvicorn.Config`` that every way of serving shares."""
    return {
        "log_level": server.log_level,
        "http": GuardedHTTPProtocol,
        "ws": BoundedCloseProtocol,
        "ws_max_size": 2 * server.max_message_bytes,
        "ws_per_message_deflate": False,
        "ws_ping_interval": server.ping_interval_s,
        "ws_ping_timeout": server.ping_timeout_s,
        "timeout_graceful_shutdown": GRACEFUL_EXIT_S,
        # a worker importing numpy, numba and the models on a busy machine needs more than
        # uvicorn's default 5 s to answer the supervisor's first health check
        "timeout_worker_healthcheck": WORKER_HEALTHCHECK_S,
        "lifespan": "on",
        "loop": ACCEPT_LOOP,
        "backlog": BACKLOG,
    }


def serve(
    models: Path,
    host: str,
    port: int,
    server: ServerSettings,
    registry: ModelRegistry | None = None,
    *,
    prepare: Callable[[Report], ModelRegistry | None] | None = None,
    sock: socket.socket | None = None,
) -> None:
    """Serve ``models`` (already loaded as ``registry``, for one worker) until SIGTERM or
    SIGINT, draining first (see ``lifecycle``). One worker listens first and starts up in
    the background (``startup``), after ``prepare`` (e.g. building the demo); a start-up
    that fails stops the server and is raised here. ``sock``: the socket one worker
    serves on, already listening (``front_door``), in place of binding ``host``:``port``."""
    raise_open_file_limit()
    if server.workers > 1:
        with drain_flag_path() as flag:
            with exported(WORKER_APP_ENV, encode_worker_app(models, server, flag)):
                supervise(host, port, server, flag)
        return
    running: list[uvicorn.Server] = []

    def stop() -> None:
        running[0].should_exit = True

    app = create_app(
        models,
        server,
        registry,
        serving_process=True,
        prepare=prepare,
        background=True,
        on_failure=stop,
    )
    config = uvicorn.Config(app, host=host, port=port, **uvicorn_options(server))
    running.append(uvicorn.Server(config))
    running[0].run(sockets=None if sock is None else [sock])
    failure = app.state.startup.failure
    if failure is not None:
        raise failure


@contextmanager
def drain_flag_path() -> Iterator[Path]:
    """Where a supervisor marks the drain: a file not yet there, in a private directory that
    is removed with it afterwards."""
    directory = Path(tempfile.mkdtemp(prefix="lipstream-drain-"))
    try:
        yield directory / DRAIN_FLAG
    finally:
        shutil.rmtree(directory, ignore_errors=True)


def supervise(host: str, port: int, server: ServerSettings, drain_flag: Path) -> None:
    """``server.workers`` worker processes of ``APP_FACTORY`` under a ``DrainingSupervisor``
    (what ``uvicorn.run`` does for several workers, with that supervisor)."""
    config = uvicorn.Config(
        APP_FACTORY,
        factory=True,
        host=host,
        port=port,
        workers=server.workers,
        **uvicorn_options(server),
    )
    sock = config.bind_socket()
    try:
        DrainingSupervisor(config, [sock], drain_flag).run()
    except KeyboardInterrupt:
        pass
