"""Liveness answered off the event loop, on a port of its own.

Sketch: in a storm of connections, a probe's TCP connection to the serving port waits in
the same accept queue as every handshake of the storm, and the event loop works through
them one batch at a time, so a liveness probe there can time out while the process is
alive and its admitted sessions are served. With ``LIPSTREAM_HEALTH_PORT`` set,
``LivenessServer`` answers ``GET /healthz`` on that port from a daemon thread, which
needs no event loop: 200 while the load monitor (``load.LoadMonitor``), a timer on the
event loop, has ticked within ``LIPSTREAM_LIVENESS_STALL_S``, and 503 once the loop has
not run it for that long. So a loop that hangs fails liveness, and a loop that is only
busy does not. Every worker binds the port with ``SO_REUSEPORT``, and the kernel spreads
the probes over them. A connection to it must send its request within
``HANDLER_TIMEOUT_S``.
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any

HEALTHZ_PATH = "/healthz"
HANDLER_TIMEOUT_S = 5.0


class _Server(ThreadingHTTPServer):
    allow_reuse_port = True
    daemon_threads = True

    def __init__(self, address: tuple[str, int], last_tick: Callable[[], float], stall_s: float):
        self.last_tick = last_tick
        self.stall_s = stall_s
        super().__init__(address, _Handler)


class _Handler(BaseHTTPRequestHandler):
    server: _Server
    timeout = HANDLER_TIMEOUT_S

    def do_GET(self) -> None:  # noqa: N802 (http.server's name)
        if self.path.split("?", 1)[0] != HEALTHZ_PATH:
            self._answer(404, {"error": "only /healthz is served on this port"})
            return
        stalled_s = time.monotonic() - self.server.last_tick()
        if stalled_s > self.server.stall_s:
            self._answer(503, {"status": "stalled", "event_loop_stalled_s": round(stalled_s, 3)})
        else:
            self._answer(200, {"status": "ok"})

    def _answer(self, status: int, body: dict[str, Any]) -> None:
        data = json.dumps(body, separators=(",", ":")).encode()
        self.send_response(status)
        self.send_header("Content-Type", "application/json")
        self.send_header("Content-Length", str(len(data)))
        self.send_header("Connection", "close")
        self.end_headers()
        self.wfile.write(data)

    def log_message(self, format: str, *args: Any) -> None:  # noqa: A002 (base signature)
        return


class LivenessServer:
    """``GET /healthz`` on ``host:port`` from a thread, judged by ``last_tick`` (monotonic
    seconds of the event loop's last timer tick) against ``stall_s``."""

    def __init__(self, host: str, port: int, last_tick: Callable[[], float], stall_s: float):
        self._server = _Server((host, port), last_tick, stall_s)
        self._thread = threading.Thread(
            target=self._server.serve_forever, name="lipstream-liveness", daemon=True
        )

    @property
    def port(self) -> int:
        return int(self._server.server_address[1])

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._server.shutdown()
        self._server.server_close()
