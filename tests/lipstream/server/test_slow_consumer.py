"""A client that never reads again: the server resets its TCP connection within a bound.

The client is a raw socket on loopback with a small receive buffer: it does
the WebSocket handshake by hand, sends one long request and never reads. The
server's send deadline ends the session; then its socket holds unsent bytes
nobody will read, and ``closing.BoundedCloseProtocol`` must reset it. (A
client that stops reading and later reads again sees the 1008
``slow_consumer`` close: ``test_limits``.)
"""

from __future__ import annotations

import base64
import os
import socket
import struct
from pathlib import Path
from urllib.parse import urlsplit

import httpx
import numpy as np
from prometheus_client.parser import text_string_to_metric_families

from lipstream.config import ServerSettings
from lipstream.engines.base import Model
from lipstream_client import (
    SUBPROTOCOL_MSGPACK,
    ClientMessage,
    Done,
    End,
    PhonemeItem,
    Phonemes,
    Start,
    encode,
)
from tests.helpers import eventually, return_frames
from tests.lipstream.server.harness import Served, client, frame_rows, serving

SEND_TIMEOUT_S = 0.3
LONG_ITEMS = tuple(PhonemeItem(("AA", "M")[i % 2], i * 0.1, (i + 1) * 0.1) for i in range(900))
SPANS = [("HH", 0.0, 0.1), ("AY1", 0.1, 0.4), ("M", 0.4, 0.5), ("sil", 0.5, 0.7)]
TCP_STATES_GONE = {"07"}  # TCP_CLOSE: no other state may remain for the server's end


def masked_frame(payload: bytes) -> bytes:
    """One final binary WebSocket frame as a client must send it (RFC 6455, masked)."""
    mask = os.urandom(4)
    length = len(payload)
    if length < 126:
        header = struct.pack("!BB", 0x82, 0x80 | length)
    elif length < 1 << 16:
        header = struct.pack("!BBH", 0x82, 0x80 | 126, length)
    else:
        header = struct.pack("!BBQ", 0x82, 0x80 | 127, length)
    data = np.frombuffer(payload, np.uint8)
    key = np.resize(np.frombuffer(mask, np.uint8), len(data))
    return header + mask + (data ^ key).tobytes()


def raw_websocket(served: Served, receive_buffer: int) -> socket.socket:
    """A handshaken msgpack connection on a socket with ``receive_buffer`` bytes of SO_RCVBUF."""
    address = urlsplit(served.http)
    sock = socket.socket()
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, receive_buffer)
    sock.settimeout(5.0)
    sock.connect((address.hostname, address.port))
    key = base64.b64encode(os.urandom(16)).decode()
    sock.sendall(
        f"GET /v1/stream HTTP/1.1\r\nHost: {address.netloc}\r\nUpgrade: websocket\r\n"
        f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
        f"Sec-WebSocket-Version: 13\r\nSec-WebSocket-Protocol: {SUBPROTOCOL_MSGPACK}"
        "\r\n\r\n".encode()
    )
    response = b""
    while not response.endswith(b"\r\n\r\n"):  # byte by byte: not one byte of frames beyond
        byte = sock.recv(1)
        assert byte, "the server closed during the handshake"
        response += byte
    assert response.startswith(b"HTTP/1.1 101 "), response
    assert f"sec-websocket-protocol: {SUBPROTOCOL_MSGPACK}".encode() in response.lower()
    return sock


def send_messages(sock: socket.socket, *messages: ClientMessage) -> None:
    for message in messages:
        sock.sendall(masked_frame(encode(message, "msgpack")))


def server_connection(served: Served, client_port: int) -> object | None:
    """uvicorn's protocol object serving the client on ``client_port``, while it is open."""
    for connection in list(served.server.server_state.connections):
        peer = getattr(connection, "client", None)
        if peer is not None and peer[1] == client_port:
            return connection
    return None


def server_socket_states(server_port: int, client_port: int) -> set[str]:
    """TCP states (hex, as in /proc/net/tcp) of the server's end of that connection."""
    states = set()
    with open("/proc/net/tcp") as table:
        next(table)
        for line in table:
            fields = line.split()
            local_port = int(fields[1].rsplit(":", 1)[1], 16)
            remote_port = int(fields[2].rsplit(":", 1)[1], 16)
            if (local_port, remote_port) == (server_port, client_port):
                states.add(fields[3])
    return states


def open_sessions(served: Served) -> float:
    """``lipstream_sessions`` from the server's ``/metrics``."""
    text = httpx.get(f"{served.http}/metrics", timeout=5).text
    [family] = [f for f in text_string_to_metric_families(text) if f.name == "lipstream_sessions"]
    [sample] = family.samples
    return float(sample.value)


def read_until_closed(sock: socket.socket) -> tuple[int, str]:
    """Bytes read until the connection ends, and how it ended ("reset" or "eof"); a read
    that waits 5 s for nothing raises TimeoutError."""
    received = 0
    while True:
        try:
            chunk = sock.recv(1 << 16)
        except ConnectionResetError:
            return received, "reset"
        if not chunk:
            return received, "eof"
        received += len(chunk)


def test_a_client_that_never_reads_again_is_reset_while_others_are_served(
    lerp_dir: Path, trained_models: dict[str, Model]
) -> None:
    settings = ServerSettings(send_timeout_s=SEND_TIMEOUT_S, max_request_frames=200_000)
    with serving(lerp_dir, settings) as served:
        slow = raw_websocket(served, receive_buffer=4096)
        server_port, client_port = slow.getpeername()[1], slow.getsockname()[1]
        # 90 s at 1000 fps: about 10 MB of frames, far beyond every buffer on the way.
        send_messages(
            slow,
            Start("slow", "viseme-lerp", "demo", fps=1000),
            Phonemes("slow", LONG_ITEMS),
            End("slow"),
        )
        connection = eventually(lambda: server_connection(served, client_port), "connected")
        transport = connection.transport  # type: ignore[attr-defined]  # uvicorn's protocol state
        eventually(lambda: transport.get_write_buffer_size() > 0, "the send stalls")

        with client(served.ws) as other:
            other.send(
                Start("a", "viseme-lerp", "demo"),
                Phonemes("a", tuple(PhonemeItem(*span) for span in SPANS)),
                End("a"),
            )
            answers = other.until_done("a")
            served_meanwhile = server_connection(served, client_port) is not None

        lifecycle = served.app.state.lifecycle
        eventually(lambda: not lifecycle.connections, "the app gives the session up")
        # The app is done, the bytes stay unsent: the socket's watch waits one send timeout
        # of no progress (when it fires: test_flush_watch, on a loop fired by hand).
        watch_timeout_s = connection.flush_watch.timeout_s  # type: ignore[attr-defined]  # uvicorn's protocol state
        eventually(lambda: server_connection(served, client_port) is None, "the socket is freed")
        sessions_after = open_sessions(served)
        states_after = server_socket_states(server_port, client_port)
        received, ending = read_until_closed(slow)
        slow.close()

    assert served_meanwhile, "the other client finished before the slow one was dealt with"
    assert isinstance(answers[-1], Done) and answers[-1].reason == "end"
    rows = frame_rows(answers)
    expected = trained_models["viseme-lerp"].synthesize(SPANS, fps=60).frames
    assert sorted(rows) == list(range(len(expected) + return_frames(60)))
    np.testing.assert_array_equal(np.array([rows[i] for i in range(len(expected))]), expected)

    # The socket's watch judges the client by the app's send timeout.
    assert watch_timeout_s == SEND_TIMEOUT_S
    assert sessions_after == 0
    # A reset, not a close that waits to flush: the kernel dropped the server's end at once
    # (a graceful close would leave it in FIN_WAIT1 holding megabytes) ...
    assert states_after <= TCP_STATES_GONE
    # ... and the client gets only what its own small buffer held, then the reset.
    assert ending == "reset"
    assert 0 < received < 1 << 18
