"""docs/reference/protocol.md's examples are a real exchange with the server.

Method: the page holds one transcript (the block after ``<!-- exchange -->``):
``→`` lines are what a client sends on the JSON subprotocol, each followed by
the ``←`` lines the server answers with. The test sends each client line to a
live loopback server of the demo's models and reads as many
answers as the page lists, then compares them field by field. Only the fields
named in ``VARIABLE`` may differ: measured timings, the frame values (which
depend on the trained model; their shape is still compared) and the numbers
inside a ``budget_infeasible`` message (they follow the server's calibration).
Every other JSON example on the page must be one of the transcript's messages,
unless a comment before it (``<!-- not in the transcript: REASON -->``) says why
it cannot be (the ``server_busy`` of an overloaded server, speech from the machine's
espeak-ng, a resumed ``start``).

Regenerate the transcript from a running server (the demo character)::

    python -m tests.lipstream.server.test_protocol_examples ws://127.0.0.1:8000/v1/stream
"""

from __future__ import annotations

import json
import re
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import ClientConnection, connect
from websockets.typing import Subprotocol

from lipstream.engines.base import Model
from tests.helpers import REPO
from tests.live_server import LiveServer, live_server

DOC_PATH = REPO / "docs" / "reference" / "protocol.md"
TRANSCRIPT = re.compile(r"<!-- exchange -->\n```text\n(.*?)```", re.DOTALL)
# A JSON example, unless a comment says why it is not in the transcript.
JSON_EXAMPLE = re.compile(r"(<!-- not in the transcript: [^>]+ -->\n)?```json\n(.*?)```", re.DOTALL)
SEND, RECEIVE = "→ ", "← "
SUBPROTOCOL = Subprotocol("lipstream.v1.json")
ANSWER_TIMEOUT_S = 20.0
QUIET_S = 0.1  # only when regenerating: the silence that ends the answers to a message
# (message type, path) of the values that may differ from the page.
VARIABLE = {
    ("frames", "data"),
    ("done", "stats.first_frame_latency_ms"),
    ("done", "stats.max_lag_ms"),
    ("done", "stats.budget_met"),
    ("error", "details.min_budget_ms"),
}
NUMBERS = re.compile(r"\d+(?:\.\d+)?")
# server_busy (an overloaded server), text and its audio (espeak-ng's own samples), resume.
MAX_EXCUSED = 6


@dataclass(frozen=True)
class Step:
    """A client message as sent (raw text) and the server's answers (decoded)."""

    sent: str
    answers: tuple[dict[str, Any], ...]


def parse_transcript(doc: str) -> list[Step]:
    match = TRANSCRIPT.search(doc)
    assert match, "docs/reference/protocol.md has no <!-- exchange --> transcript"
    steps: list[Step] = []
    for line in match.group(1).splitlines():
        if line.startswith(SEND):
            steps.append(Step(line[len(SEND) :], ()))
        elif line.startswith(RECEIVE):
            last = steps[-1]
            steps[-1] = Step(last.sent, (*last.answers, json.loads(line[len(RECEIVE) :])))
        else:
            assert not line.strip(), f"transcript line is neither sent nor received: {line!r}"
    return steps


def differences(documented: Any, received: Any, kind: str, path: str = "") -> list[str]:
    """Where ``received`` differs from ``documented``, except in the variable fields."""
    if (kind, path) in VARIABLE:
        if kind == "frames" and path == "data":
            shape = [len(row) for row in documented]
            got = [len(row) for row in received] if isinstance(received, list) else received
            return [] if got == shape else [f"{path}: rows of {got} values, documented {shape}"]
        same_type = type(documented) is type(received) or {type(documented), type(received)} <= {
            int,
            float,
        }
        return [] if same_type else [f"{path}: {received!r} is not like {documented!r}"]
    if isinstance(documented, dict) and isinstance(received, dict):
        found = []
        for key in sorted(set(documented) | set(received)):
            inner = f"{path}.{key}" if path else key
            if key not in received or key not in documented:
                where = "missing from the answer" if key not in received else "not documented"
                found.append(f"{inner}: {where}")
            else:
                found += differences(documented[key], received[key], kind, inner)
        return found
    if documented != received:
        return [f"{path}: received {received!r}, documented {documented!r}"]
    return []


def compare(documented: dict[str, Any], received: dict[str, Any]) -> list[str]:
    kind = str(documented.get("type"))
    if kind == "error" and documented.get("code") == "budget_infeasible":
        documented = {**documented, "message": NUMBERS.sub("N", documented["message"])}
        received = {**received, "message": NUMBERS.sub("N", str(received.get("message")))}
    return differences(documented, received, kind)


def answers(socket: ClientConnection, count: int) -> list[dict[str, Any]]:
    return [json.loads(socket.recv(timeout=ANSWER_TIMEOUT_S)) for _ in range(count)]


def replay(url: str, steps: list[Step]) -> list[tuple[Step, list[dict[str, Any]]]]:
    """Send each step's message and read as many answers as it documents."""
    replies = []
    with connect(url, subprotocols=[SUBPROTOCOL], proxy=None) as socket:
        assert socket.subprotocol == SUBPROTOCOL
        for step in steps:
            socket.send(step.sent)
            replies.append((step, answers(socket, len(step.answers))))
    return replies


DOC = DOC_PATH.read_text(encoding="utf-8")
STEPS = parse_transcript(DOC)


@pytest.fixture(scope="module")
def served(all_models_dir: Path) -> Iterator[LiveServer]:
    with live_server(all_models_dir) as server:
        yield server


def test_transcript_covers_every_message_type() -> None:
    sent = {json.loads(step.sent)["type"] for step in STEPS if step.sent.endswith("}")}
    received = {answer["type"] for step in STEPS for answer in step.answers}
    assert sent == {"start", "phonemes", "audio", "end", "cancel", "interrupt"}
    assert received == {"ready", "frames", "done", "error"}


def test_every_json_example_is_a_message_of_the_transcript() -> None:
    messages = [json.loads(step.sent) for step in STEPS if step.sent.endswith("}")]
    messages += [answer for step in STEPS for answer in step.answers]
    found = JSON_EXAMPLE.findall(DOC)
    examples = [json.loads(text) for excused, text in found if not excused]
    assert len(examples) >= 10 and len(found) - len(examples) <= MAX_EXCUSED
    assert [example for example in examples if example not in messages] == []


def test_comparison_catches_a_changed_field_and_allows_variable_ones() -> None:
    documented = {"type": "done", "id": "a", "stats": {"frames": 3, "max_lag_ms": 1.5}}
    assert compare(documented, {**documented, "stats": {"frames": 3, "max_lag_ms": 9}}) == []
    assert compare(documented, {**documented, "stats": {"frames": 4, "max_lag_ms": 1.5}}) == [
        "stats.frames: received 4, documented 3"
    ]
    frames = {"type": "frames", "data": [[0.1, 0.2]]}
    assert compare(frames, {"type": "frames", "data": [[0.5, 0.6]]}) == []
    assert compare(frames, {"type": "frames", "data": [[0.5, 0.6], [0.1, 0.1]]}) != []
    assert compare({"type": "ready", "fidelity": "exact"}, {"type": "ready"}) == [
        "fidelity: missing from the answer"
    ]


@pytest.mark.parametrize("engine", ["viseme-lerp", "anime-graph"])
def test_rung_table_lists_the_ladder_the_model_declares(
    engine: str, trained_models: dict[str, Model]
) -> None:
    row = re.search(rf"^\| `{engine}` \| (.*?) \|", DOC, flags=re.MULTILINE)
    assert row, f"no rung row for {engine}"
    documented = re.findall(r"`([a-z0-9_]+)`", row.group(1))
    assert documented == [rung.name for rung in trained_models[engine].fidelity_ladder()]


def test_the_server_answers_as_the_transcript_shows(served: LiveServer) -> None:
    mismatches = []
    for step, received in replay(served.ws, STEPS):
        for documented, answer in zip(step.answers, received, strict=True):
            mismatches += [
                f"after {step.sent[:60]}…: {item}" for item in compare(documented, answer)
            ]
    assert mismatches == []


def regenerate(url: str) -> str:
    """The transcript's lines as the server at ``url`` answers the page's client messages."""
    lines = []
    with connect(url, subprotocols=[SUBPROTOCOL], proxy=None) as socket:
        for step in STEPS:
            socket.send(step.sent)
            lines.append(SEND + step.sent)
            while True:
                try:
                    text = socket.recv(timeout=QUIET_S)
                except (TimeoutError, ConnectionClosed):
                    break
                assert isinstance(text, str)  # the JSON subprotocol sends text frames
                lines.append(RECEIVE + text)
    return "\n".join(lines)


if __name__ == "__main__":
    print(regenerate(sys.argv[1] if len(sys.argv) > 1 else "ws://127.0.0.1:8000/v1/stream"))
