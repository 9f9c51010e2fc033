"""The listening socket of ``lipstream serve``, answered before the server is imported.

Sketch: the server's imports (numpy, scipy, numba, FastAPI, the engines) take
seconds, more on a busy machine, and a probe that finds no listener in that
time reports the server dead. So the command binds its socket first, with the
standard library alone, and a ``FrontDoor`` thread answers on it: ``/healthz``
200 ``{"status": "ok"}``, ``/readyz`` 503 with the phase ``starting`` and the
latest status line (as the app's own ``/readyz`` does later), and any other
path 503 ``starting`` with ``Retry-After``. Each connection gets one answer
and is closed; its request head is read with a deadline and a size cap, so a
slow or hostile peer holds the door for at most ``READ_DEADLINE_S``.
``hand_over`` stops the thread and returns the still-open socket for uvicorn
(``Server.run(sockets=...)``): connections arriving in between wait in the
listen backlog, none is refused.
"""

from __future__ import annotations

import json
import selectors
import socket
import threading
import time
from collections.abc import Callable

from lipstream_client.errors import STARTING

STARTING_PHASE = "starting"
POLL_S = 0.05
READ_DEADLINE_S = 1.0
MAX_HEAD_BYTES = 8192
# The kernel caps it at net.core.somaxconn (4096 by default since Linux 5.4). A deep queue
# lets a connection flood's burst wait there (the accept loop takes a bounded number per
# turn) instead of filling it, where every newcomer's SYN, a probe's too, is dropped and
# retried only after 1 s.
BACKLOG = 8192
RETRY_AFTER_S = 2


def bind(host: str, port: int) -> socket.socket:
    """A listening TCP socket on ``host``:``port`` (as uvicorn would bind it)."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
        sock.listen(BACKLOG)
    except OSError:
        sock.close()
        raise
    sock.set_inheritable(True)
    return sock


def answer(head: bytes, status_line: str, elapsed_s: float) -> bytes:
    """The whole HTTP/1.1 response to the request whose head is ``head``."""
    path = _path(head)
    headers = ""
    body: dict[str, object]
    if path == "/healthz":
        code, body = "200 OK", {"status": "ok"}
    elif path == "/readyz":
        code = "503 Service Unavailable"
        body = {
            "ready": False,
            "phase": STARTING_PHASE,
            "status": status_line,
            "phase_s": round(elapsed_s, 1),
            "elapsed_s": round(elapsed_s, 1),
            "failed_models": [],
        }
    else:
        code, headers = "503 Service Unavailable", f"retry-after: {RETRY_AFTER_S}\r\n"
        message = (
            f"the server is starting up ({status_line or 'importing'}); "
            "retry once GET /readyz answers 200"
        )
        body = {
            "error": {"code": STARTING, "message": message, "details": {"phase": STARTING_PHASE}}
        }
    payload = json.dumps(body).encode()
    return (
        f"HTTP/1.1 {code}\r\ncontent-type: application/json\r\ncontent-length: {len(payload)}"
        f"\r\n{headers}connection: close\r\n\r\n"
    ).encode() + payload


def _path(head: bytes) -> str:
    """The path of the request line (``METHOD /path HTTP/1.x``), without its query; ``""``
    when the line is not one."""
    request_line = head.split(b"\r\n", 1)[0].split(b" ")
    if len(request_line) != 3 or not request_line[0].isalpha():
        return ""
    if not request_line[2].startswith(b"HTTP/"):
        return ""
    return request_line[1].split(b"?", 1)[0].decode("latin-1")


class FrontDoor:
    """Answers on ``sock`` from a thread until ``hand_over``; ``note`` sets the status line
    ``/readyz`` shows."""

    def __init__(self, sock: socket.socket, clock: Callable[[], float] = time.monotonic) -> None:
        self._sock = sock
        self._clock = clock
        self._began = clock()
        self._line = ""
        self._stopping = threading.Event()
        self._thread = threading.Thread(target=self._run, name="lipstream-front-door", daemon=True)

    def start(self) -> FrontDoor:
        self._thread.start()
        return self

    def note(self, line: str) -> None:
        self._line = line

    def hand_over(self) -> socket.socket:
        """Stop answering; the socket, still listening, for the real server."""
        self._stopping.set()
        self._thread.join()
        return self._sock

    def _run(self) -> None:
        with selectors.DefaultSelector() as selector:
            selector.register(self._sock, selectors.EVENT_READ)
            while not self._stopping.is_set():
                if selector.select(POLL_S):
                    self._serve_one()

    def _serve_one(self) -> None:
        try:
            connection, _ = self._sock.accept()
        except (BlockingIOError, InterruptedError):
            return
        with connection:
            try:
                head = _read_head(connection, self._clock() + READ_DEADLINE_S, self._clock)
                response = answer(head, self._line, self._clock() - self._began)
                connection.sendall(response)
            except OSError:
                return  # the peer went away; the next one is answered


def _read_head(connection: socket.socket, deadline: float, clock: Callable[[], float]) -> bytes:
    """Bytes up to the end of the request head, at most ``MAX_HEAD_BYTES``, until
    ``deadline``."""
    head = b""
    while b"\r\n\r\n" not in head and len(head) < MAX_HEAD_BYTES:
        remaining = deadline - clock()
        if remaining <= 0:
            break
        connection.settimeout(remaining)
        try:
            chunk = connection.recv(MAX_HEAD_BYTES - len(head))
        except TimeoutError:
            break
        if not chunk:
            break
        head += chunk
    return head
