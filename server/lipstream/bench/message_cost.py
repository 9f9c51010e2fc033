"""App-level CPU per ``phonemes`` message: the server's app beside the reference server's.

Sketch: ``lipstream loadtest cpu`` measures whole processes under paced load, and on a
shared machine its rounds move by more than one cut of the per-message path is worth.
This bench takes the sockets, the event loop's polling and the load generator away: both
ASGI apps (``create_app`` serving one engine's model, and the capacity tool's reference
app imitating that engine's ``ready``) run in one process and one event loop, each
connection driven by a ``receive`` that hands over pre-encoded messages at once and a
``send`` that drops what it gets. A leg is one connection streaming ``requests``
requests, each a synthetic clip of ``clip_s`` seconds sent one ``phonemes`` message per
phoneme (as the load test sends them), then ``end``; its figure is the process's CPU time
over the ``phonemes`` messages. Legs alternate server, reference, ``rounds`` times, after
one warm-up leg each; reported are each side's median and the ratio of the medians. Every
rung's calibration is fixed (as in the tests), so the rung follows from the budget and the
models' lookahead alone.

The file imports ``lipstream`` absolutely, so it also runs as a script against another
tree's code (``PYTHONPATH`` naming that tree's ``server`` and ``client_sdk``)::

    python -m lipstream.bench.message_cost --models DIR --engine anime-graph \\
        --rounds 7 --json bench/message_cost.json
"""

from __future__ import annotations

import argparse
import asyncio
import datetime
import statistics
import subprocess
import time
from collections.abc import Awaitable, Callable, Sequence
from pathlib import Path
from typing import Any
from unittest.mock import patch

import lipstream.server.catalog as catalog_module
from lipstream.engines.base import Model, Rung
from lipstream.loadtest.clips import synthetic_clip
from lipstream.loadtest.reference import Receive, ReferenceApp, ReferenceTraffic, Scope, Send
from lipstream.results_file import machine, script_command, write_results
from lipstream.server.app import create_app
from lipstream.server.calibration import ComputeCost
from lipstream_client import End, PhonemeItem, Phonemes, Ready, Start, decode, encode

FIXED_COMPUTE_MS = 1.0
SUBPROTOCOL = "lipstream.v1.msgpack"
Event = dict[str, Any]
App = Callable[[Scope, Receive, Send], Awaitable[None]]


def _fixed_cost(model: Model, rung: Rung, *checks: object) -> ComputeCost:
    return ComputeCost(FIXED_COMPUTE_MS, FIXED_COMPUTE_MS, per_frame_ms=0.001)


def leg_events(
    engine: str, character: str, requests: int, clip_s: float, budget_ms: float
) -> tuple[list[Event], int]:
    """The ASGI events of one leg's connection, and how many are ``phonemes`` messages."""
    events: list[Event] = [{"type": "websocket.connect"}]
    phonemes = 0
    for number in range(requests):
        identifier = f"r{number}"
        start = Start(identifier, engine, character, 60.0, latency_budget_ms=budget_ms)
        events.append(_event(encode(start, "msgpack")))
        for phoneme, begin, end in synthetic_clip(clip_s, seed=number):
            item = PhonemeItem(phoneme, begin, end)
            events.append(_event(encode(Phonemes(identifier, (item,)), "msgpack")))
            phonemes += 1
        events.append(_event(encode(End(identifier), "msgpack")))
    return events, phonemes


def _event(payload: bytes) -> Event:
    return {"type": "websocket.receive", "bytes": payload}


def stream_scope(state: dict[str, Any]) -> Event:
    return {
        "type": "websocket",
        "asgi": {"version": "3.0"},
        "scheme": "ws",
        "path": "/v1/stream",
        "raw_path": b"/v1/stream",
        "root_path": "",
        "query_string": b"",
        "headers": [],
        "subprotocols": [SUBPROTOCOL],
        "client": ("127.0.0.1", 50000),
        "server": ("127.0.0.1", 8000),
        "state": state,
    }


async def run_leg(app: App, scope: Event, events: list[Event]) -> list[bytes]:
    """Serve one connection that sends ``events``; the payloads the app sent."""
    pending = list(reversed(events))
    sent: list[bytes] = []

    async def receive() -> Event:
        if pending:
            return pending.pop()
        await asyncio.sleep(0)
        return {"type": "websocket.disconnect", "code": 1000}

    async def send(message: Any) -> None:
        payload = message.get("bytes")
        if isinstance(payload, bytes):
            sent.append(payload)

    await app(scope, receive, send)
    return sent


async def _cpu_per_message(app: App, scope: Event, events: list[Event], count: int) -> float:
    began = time.process_time()
    await run_leg(app, scope, events)
    return 1e6 * (time.process_time() - began) / count


async def compare(
    models: Path,
    engine: str,
    character: str,
    rounds: int,
    requests: int,
    clip_s: float,
    budget_ms: float,
) -> dict[str, Any]:
    """The legs and the summary of one comparison."""
    with patch("lipstream.server.catalog.measure", _fixed_cost):
        legs = await _legs(models, engine, character, rounds, (requests, clip_s, budget_ms))
    ready, sent, reference_sent, server_us, reference_us, count = legs
    server_median = statistics.median(server_us)
    reference_median = statistics.median(reference_us)
    return {
        "engine": engine,
        "character": character,
        "fidelity": ready.fidelity,
        "latency_budget_ms": budget_ms,
        "requests": requests,
        "clip_s": clip_s,
        "phonemes_messages": count,
        "messages_sent": {"server": len(sent), "reference": len(reference_sent)},
        "rounds": rounds,
        "server_us": server_us,
        "reference_us": reference_us,
        "server_median_us": server_median,
        "reference_median_us": reference_median,
        "ratio": server_median / reference_median,
        "revision": _revision(),
    }


async def _legs(
    models: Path, engine: str, character: str, rounds: int, leg: tuple[int, float, float]
) -> tuple[Ready, list[bytes], list[bytes], list[float], list[float], int]:
    """The warm-up legs' answers and every round's figures (µs per message) of both apps."""
    requests, clip_s, budget_ms = leg
    app = create_app(models)
    async with app.router.lifespan_context(app) as lifespan_state:
        state = dict(lifespan_state or {})
        startup = state["startup"]
        while startup.server is None:
            await asyncio.sleep(0.1)
        events, count = leg_events(engine, character, requests, clip_s, budget_ms)
        scope = stream_scope(state)
        sent = await run_leg(app, scope, events)  # warm-up, and the engine's ready
        ready = decode(sent[0], "msgpack")
        if not isinstance(ready, Ready):
            raise RuntimeError(f"the server answered {ready!r}, not ready")
        traffic = ReferenceTraffic(ready.channels, ready.lookahead_ms, ready.fidelity)
        reference = ReferenceApp(traffic)
        reference_scope = stream_scope({})
        reference_sent = await run_leg(reference, reference_scope, events)
        server_us: list[float] = []
        reference_us: list[float] = []
        for _ in range(rounds):
            server_us.append(await _cpu_per_message(app, scope, events, count))
            reference_us.append(await _cpu_per_message(reference, reference_scope, events, count))
    return ready, sent, reference_sent, server_us, reference_us, count


def _revision() -> str:
    here = Path(catalog_module.__file__).resolve().parents[3]
    result = subprocess.run(
        ["git", "-C", str(here), "describe", "--always", "--dirty"],
        capture_output=True,
        text=True,
        check=False,
    )
    return result.stdout.strip() if result.returncode == 0 else str(here)


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--models", type=Path, required=True, help="model directory")
    parser.add_argument("--engine", required=True, help="the engine to stream")
    parser.add_argument("--character", default="demo", help="the character to stream")
    parser.add_argument("--rounds", type=int, default=7, help="server/reference leg pairs")
    parser.add_argument("--requests", type=int, default=5, help="requests per leg")
    parser.add_argument("--clip", type=float, default=10.0, help="seconds per request")
    parser.add_argument("--budget-ms", type=float, default=20.0, help="latency_budget_ms")
    parser.add_argument("--json", type=Path, help="write the result here")
    args = parser.parse_args(argv)
    result = asyncio.run(
        compare(
            args.models,
            args.engine,
            args.character,
            args.rounds,
            args.requests,
            args.clip,
            args.budget_ms,
        )
    )
    print(
        f"{result['engine']} ({result['fidelity']}): server {result['server_median_us']:.1f} µs "
        f"per phonemes message, reference {result['reference_median_us']:.1f}, "
        f"ratio {result['ratio']:.2f} ({result['revision']})"
    )
    if args.json is not None:
        date = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
        command = script_command("lipstream.bench.message_cost", argv)
        write_results({"machine": machine(), "date": date, "command": command, **result}, args.json)


if __name__ == "__main__":
    main()
