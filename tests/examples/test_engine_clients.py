"""The Godot and Unity clients' message exchange, run in Python against a real server.

Neither engine runs here, so this test performs what ``examples/godot/lipstream_client.gd``
and ``examples/unity/LipstreamClient.cs`` do on the wire: the JSON subprotocol, then
``start`` (with ``output.retarget``), ``text`` and ``end`` sent back to back, then the
server's messages read with the fields the clients read, in the order they rely on
(``ready`` first; all of the text's ``audio`` before its first ``frames``, since they
build the speech clip there; frames contiguous from 0; ``done`` last). It also reads
the clients' sources, so a client that sends or reads a field the exchange here does
not is a failure. The C# is compiled by Mono's ``mcs``, when installed, against
Newtonsoft.Json and ``unity_stubs.cs`` (the Unity API it calls, declared with Unity's
signatures); the GDScript is parsed and linted by gdtoolkit (GDScript 2.0's grammar and
its default style rules), which checks its syntax, not what Godot makes of it.
"""

from __future__ import annotations

import base64
import json
import re
import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.helpers import REPO, VRM1_EXPRESSIONS
from tests.live_server import LiveServer, live_server

GODOT = REPO / "examples" / "godot" / "lipstream_client.gd"
UNITY = REPO / "examples" / "unity" / "LipstreamClient.cs"
UNITY_STUBS = Path(__file__).with_name("unity_stubs.cs")
NEWTONSOFT = Path(
    "/usr/lib/cli/Newtonsoft.Json-5.0/Newtonsoft.Json.dll"
)  # Debian's libnewtonsoft-json5.0-cil
MAX_LINES = 150
WAIT_S = 60.0  # a bound on a busy machine, not a speed claim
TEXT = "Hello from the game engine."


def client_messages(request: str, retarget: str) -> list[dict[str, Any]]:
    """What both clients send for ``say(TEXT)`` with their default settings."""
    return [
        {
            "v": 1,
            "type": "start",
            "id": request,
            "engine": "viseme-lerp",
            "character": "demo",
            "fps": 60.0,
            "output": {"retarget": retarget},
        },
        {"v": 1, "type": "text", "id": request, "text": TEXT, "voice": "en-us"},
        {"v": 1, "type": "end", "id": request},
    ]


# The fields the clients read, by message type (every message: type and id; done: stats.frames).
READ = {
    "ready": {"channels", "fps"},
    "audio": {"sample_rate", "pcm16"},
    "frames": {"first_frame", "data"},
    "done": {"stats"},
    "error": {"code", "message", "fatal"},
}
READ_IN_SOURCES = {"type", "id", "frames"}.union(*READ.values())


@pytest.fixture(scope="module")
def served(lerp_dir: Path) -> Iterator[LiveServer]:
    with live_server(lerp_dir) as server:
        yield server


def exchange(served: LiveServer, sent: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Send ``sent`` back to back on a JSON connection; the server's messages up to ``done``
    or a fatal error."""
    from websockets.sync.client import connect
    from websockets.typing import Subprotocol

    received = []
    with connect(served.ws, subprotocols=[Subprotocol("lipstream.v1.json")], proxy=None) as ws:
        assert ws.subprotocol == "lipstream.v1.json"
        for message in sent:
            ws.send(json.dumps(message))
        for _ in range(100_000):
            frame = ws.recv(timeout=WAIT_S)
            assert isinstance(frame, str)  # a text frame, as the clients read
            received.append(json.loads(frame))
            if (
                received[-1]["type"] == "done"
                or received[-1]["type"] == "error"
                and received[-1]["fatal"]
            ):
                return received
    raise AssertionError("no done")


def test_text_request_exchange_as_the_clients_do_it(served: LiveServer) -> None:
    received = exchange(served, client_messages("godot-1", "vrm1"))
    types = [message["type"] for message in received]
    assert types[0] == "ready" and types[-1] == "done"
    assert set(types) == {"ready", "audio", "frames", "done"}
    assert all(message["id"] == "godot-1" for message in received)
    last_audio = max(i for i, kind in enumerate(types) if kind == "audio")
    assert last_audio < types.index("frames")  # the clients build the speech at the first frames
    for message in received:
        assert READ[message["type"]] <= set(message)

    ready = received[0]
    channels = ready["channels"]
    assert sorted(channels) == sorted(VRM1_EXPRESSIONS)
    assert ready["fps"] == 60.0

    samples = 0
    rate = None
    for message in received:
        if message["type"] == "audio":
            pcm = base64.b64decode(message["pcm16"], validate=True)
            assert len(pcm) % 2 == 0 and len(pcm) > 0
            rate = rate or message["sample_rate"]
            assert message["sample_rate"] == rate and isinstance(rate, int)
            assert abs(message["start"] - samples / rate) < 0.5 / rate  # chunks follow on, in order
            samples += len(pcm) // 2

    rows: list[list[float]] = []
    for message in received:
        if message["type"] == "frames":
            assert message["first_frame"] == len(rows)  # the clients append contiguous blocks
            assert all(len(row) == len(channels) for row in message["data"])
            rows += message["data"]
    assert received[-1]["stats"]["frames"] == len(rows)
    assert (
        rate is not None and len(rows) >= samples / rate * ready["fps"]
    )  # frames cover the speech
    assert max(row[channels.index("aa")] for row in rows) > 0.1  # the mouth opens


def test_a_refused_request_ends_with_the_fields_the_clients_read(served: LiveServer) -> None:
    received = exchange(served, client_messages("unity-1", "no-such-rig"))
    error = received[-1]
    assert [m["type"] for m in received] == ["error"]
    assert READ["error"] <= set(error) and error["fatal"] is True and error["id"] == "unity-1"
    assert "no-such-rig" in error["message"]


def gdscript_sent(source: str) -> list[set[str]]:
    calls = re.findall(r"_send\((\{.*?\})\)\n", source, re.DOTALL)
    return [set(re.findall(r'"(\w+)":', call)) for call in calls]


def csharp_sent(source: str) -> list[set[str]]:
    calls = re.findall(r"Send\(new (\{.*\})\);", source)
    return [
        set(re.findall(r"\b([a-z]\w*)\b", re.sub(r'"[^"]*"|\bnew\b|\d+', "", call)))
        for call in calls
    ]


def keys(message: dict[str, Any]) -> set[str]:
    found = set(message)
    for value in message.values():
        if isinstance(value, dict):
            found |= keys(value)
    return found


@pytest.mark.parametrize("client", [GODOT, UNITY], ids=["godot", "unity"])
def test_the_clients_send_and_read_what_the_exchange_covers(client: Path) -> None:
    source = client.read_text()
    assert len(source.splitlines()) < MAX_LINES
    expected = [keys(message) for message in client_messages("x", "vrm1")]
    if client == GODOT:
        assert [sent | {"v"} for sent in gdscript_sent(source)] == expected  # _send adds v
    else:
        assert csharp_sent(source) == expected
    read = set(re.findall(r'\["(\w+)"\](?!\s*=[^=])', source))  # not an assignment
    assert read == READ_IN_SOURCES
    assert "lipstream.v1.json" in source


@pytest.mark.skipif(
    shutil.which("mcs") is None or not NEWTONSOFT.exists(),
    reason="needs Mono's mcs and Newtonsoft.Json (Debian: mono-mcs, libnewtonsoft-json5.0-cil)",
)
def test_the_unity_client_compiles(tmp_path: Path) -> None:
    compiled = subprocess.run(
        [
            "mcs",
            "-target:library",
            f"-out:{tmp_path / 'client.dll'}",
            f"-r:{NEWTONSOFT}",
            "-warnaserror",
            str(UNITY),
            str(UNITY_STUBS),
        ],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert compiled.returncode == 0, compiled.stdout + compiled.stderr


def test_the_godot_client_parses_and_lints() -> None:
    from gdtoolkit.linter import DEFAULT_CONFIG, lint_code
    from gdtoolkit.parser import parser

    source = GODOT.read_text()
    parser.parse(source)  # raises on a syntax error
    assert lint_code(source, DEFAULT_CONFIG) == []
