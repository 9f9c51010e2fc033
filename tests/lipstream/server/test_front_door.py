"""The front door answers on the bound socket while the server imports, then hands it over.

A real socket on loopback and a real HTTP client; the hand-over runs a real uvicorn
server on the same socket. The clock the door reports its elapsed time with is injected.
"""

from __future__ import annotations

import asyncio
import json
import socket
import threading
from pathlib import Path

import httpx
import uvicorn

from lipstream.config import ServerSettings
from lipstream.server.app import create_app
from lipstream.server.front_door import FrontDoor, answer, bind
from lipstream.server.runner import uvicorn_options
from tests.helpers import eventually
from tests.live_server import READY_POLLS

WAIT_S = 120.0


class Clock:
    def __init__(self) -> None:
        self.now = 50.0

    def __call__(self) -> float:
        return self.now


def test_the_door_answers_health_names_the_phase_and_refuses_the_rest() -> None:
    clock = Clock()
    sock = bind("127.0.0.1", 0)
    base = f"http://127.0.0.1:{sock.getsockname()[1]}"
    door = FrontDoor(sock, clock).start()
    try:
        door.note("importing the server ...")
        clock.now += 3.25
        health = httpx.get(f"{base}/healthz", timeout=WAIT_S)
        assert (health.status_code, health.json()) == (200, {"status": "ok"})
        ready = httpx.get(f"{base}/readyz?verbose=1", timeout=WAIT_S)
        assert ready.status_code == 503
        assert ready.json() == {
            "ready": False,
            "phase": "starting",
            "status": "importing the server ...",
            "phase_s": 3.2,
            "elapsed_s": 3.2,
            "failed_models": [],
        }
        refused = httpx.post(f"{base}/v1/synthesize", json={"engine": "dam"}, timeout=WAIT_S)
        assert (refused.status_code, refused.headers["retry-after"]) == (503, "2")
        assert refused.json()["error"]["code"] == "starting"
        assert refused.json()["error"]["details"] == {"phase": "starting"}
    finally:
        door.hand_over().close()


def test_a_silent_or_garbled_peer_does_not_shut_the_door() -> None:
    sock = bind("127.0.0.1", 0)
    address = sock.getsockname()
    door = FrontDoor(sock).start()
    try:
        with (
            socket.create_connection(address) as silent,
            socket.create_connection(address) as garbled,
        ):
            garbled.sendall(b"\x16\x03\x01\x00\xff" * 3000)  # a TLS hello, far over the head cap
            health = httpx.get(f"http://127.0.0.1:{address[1]}/healthz", timeout=WAIT_S)
            assert health.status_code == 200
            silent.settimeout(WAIT_S)
            assert silent.recv(64).startswith(b"HTTP/1.1 503")  # answered once its deadline passed
    finally:
        door.hand_over().close()


def test_unreadable_request_lines_get_the_refusal() -> None:
    for head in (b"", b"GARBAGE", b"\xff\xfe /healthz\r\n\r\n"):
        response = answer(head, "", 0.0)
        status, _, body = response.partition(b"\r\n\r\n")
        assert status.startswith(b"HTTP/1.1 503 ")
        assert json.loads(body)["error"]["code"] == "starting"


def test_the_socket_handed_over_is_served_by_uvicorn_and_loses_no_connection(
    lerp_dir: Path,
) -> None:
    sock = bind("127.0.0.1", 0)
    address = sock.getsockname()
    door = FrontDoor(sock).start()
    assert httpx.get(f"http://127.0.0.1:{address[1]}/healthz", timeout=WAIT_S).status_code == 200
    handed = door.hand_over()
    waiting = socket.create_connection(address)  # arrives between the door and uvicorn
    waiting.sendall(b"GET /healthz HTTP/1.1\r\nhost: x\r\nconnection: close\r\n\r\n")

    settings = ServerSettings(log_level="warning")
    app = create_app(lerp_dir, settings, background=True)
    config = uvicorn.Config(app, **uvicorn_options(settings))
    server = uvicorn.Server(config)
    loop = asyncio.new_event_loop()
    thread = threading.Thread(
        target=loop.run_until_complete, args=(server.serve(sockets=[handed]),), daemon=True
    )
    thread.start()
    try:
        waiting.settimeout(WAIT_S)
        reply = b""
        while chunk := waiting.recv(4096):
            reply += chunk
        assert reply.startswith(b"HTTP/1.1 200 OK")
        assert reply.endswith(b'{"status":"ok"}')
        eventually(
            lambda: (
                httpx.get(f"http://127.0.0.1:{address[1]}/readyz", timeout=WAIT_S).status_code
                == 200
            ),
            "the server turned ready",
            READY_POLLS,
        )
    finally:
        waiting.close()
        server.should_exit = True
        thread.join(timeout=15)
        loop.close()
