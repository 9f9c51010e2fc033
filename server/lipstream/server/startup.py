"""A server's start-up as phases the HTTP routes can report while it runs.

Sketch: ``lipstream serve`` listens first and starts up behind it, so
``/healthz`` answers from the first second of a start that may build the demo
character (minutes on a busy machine). ``Startup`` is the record the routes
read: the phase (``starting``, ``building``, ``loading``, ``calibrating``,
then ``ready``, or ``failed``), the latest status line, and, once ready, the
``ServerState``. Until then ``/readyz`` answers 503 with the phase, and
synthesis (REST, WebSocket, the phoneme-map routes) is refused with
``starting``. The start-up itself runs on a thread (``run_in_background``);
a failure is recorded as the phase ``failed`` with its reason and handed to
``on_failure`` (``lipstream serve`` then stops and exits 2 with that line).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from lipstream_client.errors import STARTING

from ..errors import LipstreamError
from ..status import Report
from .front_door import STARTING_PHASE
from .state import ServerState

BUILDING = "building"
LOADING = "loading"
CALIBRATING = "calibrating"
READY = "ready"
FAILED = "failed"
PHASES = (STARTING_PHASE, BUILDING, LOADING, CALIBRATING, READY, FAILED)


class NotReady(LipstreamError):
    """A route that needs the models was called while the server starts up."""

    code = STARTING


@dataclass
class Startup:
    """The phase a server's start-up is in, its latest status line and, once ready, the
    ``ServerState`` (read from any thread; written by the start-up's)."""

    clock: Callable[[], float] = time.monotonic
    phase: str = STARTING_PHASE
    line: str = ""
    failure: LipstreamError | None = None
    server: ServerState | None = None
    began: float = field(default=0.0)
    phase_began: float = field(default=0.0)

    def __post_init__(self) -> None:
        self.began = self.phase_began = self.clock()

    def enter(self, phase: str) -> None:
        self.phase, self.phase_began = phase, self.clock()

    def note(self, line: str) -> None:
        self.line = line

    def reporting(self, report: Report) -> Report:
        """``report`` that also notes each line as the latest status."""

        def noted(line: str) -> None:
            self.note(line)
            report(line)

        return noted

    def ready(self, server: ServerState) -> None:
        self.server = server
        self.enter(READY)

    def fail(self, error: LipstreamError) -> None:
        self.failure = error
        self.line = f"error [{error.code}]: {error.where + ': ' if error.where else ''}"
        self.line += error.message
        self.enter(FAILED)

    def serving(self) -> ServerState:
        """The server state, or ``NotReady`` naming the phase."""
        server = self.server
        if server is None:
            raise self.not_ready()
        return server

    def not_ready(self) -> NotReady:
        """The error that refuses a request now, naming the phase as ``where``."""
        return NotReady(
            f"the server is starting up ({self.phase}: {self.line or 'under way'}); "
            "retry once GET /readyz answers 200",
            where=self.phase,
        )

    def report(self) -> dict[str, object]:
        """``/readyz``'s body before the server is ready."""
        now = self.clock()
        return {
            "ready": False,
            "phase": self.phase,
            "status": self.line,
            "phase_s": round(now - self.phase_began, 1),
            "elapsed_s": round(now - self.began, 1),
            "failed_models": [],
        }


def run_in_background(
    work: Callable[[], None], startup: Startup, on_failure: Callable[[], None]
) -> threading.Thread:
    """Run ``work`` on a daemon thread; a failure becomes ``startup.fail`` then
    ``on_failure()``."""

    def run() -> None:
        try:
            work()
        except LipstreamError as error:
            startup.fail(error)
            on_failure()
        except Exception as error:  # a fault in start-up must still stop the server
            startup.fail(
                LipstreamError(
                    f"start-up failed ({type(error).__name__}: {error})",
                    where=startup.phase,
                    code="internal_error",
                )
            )
            on_failure()

    thread = threading.Thread(target=run, name="lipstream-startup", daemon=True)
    thread.start()
    return thread


def server_of(app_state: Mapping[str, Any]) -> ServerState | None:
    """The ``ServerState`` of the app whose lifespan state is ``app_state``, once ready."""
    startup = app_state.get("startup")
    return startup.server if isinstance(startup, Startup) else None
