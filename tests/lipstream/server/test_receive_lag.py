"""The receive lag, on a real server: a message that waits between reaching the process and
the app taking it is counted, in ``lipstream_receive_lag_seconds`` and in the frame lag of
the frames it covers (both measured from when its bytes reached the process, not from when
the app read it)."""

from __future__ import annotations

import asyncio
import re
import threading
import time
from pathlib import Path

import httpx

from lipstream_client import Frames, PhonemeItem, Phonemes, Ready, Start
from tests.lipstream.server.harness import Served, client, serving

HOLD_S = 0.3  # each of the loop's turns while the message waits: far above its 1 ms
TURNS = 6


async def hold_every_turn(held: threading.Event) -> None:
    """Sleep ``HOLD_S`` in each of ``TURNS`` turns of the event loop: a message whose bytes
    arrive meanwhile is read by the transport in one turn and taken by the app in a later
    one, after a hold."""
    held.set()
    for _ in range(TURNS):
        time.sleep(HOLD_S)
        await asyncio.sleep(0)


def observations_above(served: Served, metric: str, bound: str) -> tuple[float, float]:
    """(observations of ``metric`` in all, those above the bucket ``bound``), summed over
    its labels."""
    text = httpx.get(f"{served.http}/metrics", timeout=30).text
    total = above = 0.0
    for line in text.splitlines():
        found = re.match(rf'^{metric}_bucket{{(.*)le="([^"]+)"}} (\S+)$', line)
        if found is None:
            continue
        if found.group(2) == "+Inf":
            total += float(found.group(3))
        elif found.group(2) == bound:
            above -= float(found.group(3))
    return total, total + above


def test_a_message_held_between_socket_and_app_shows_in_the_receive_and_frame_lag(
    lerp_dir: Path,
) -> None:
    with serving(lerp_dir) as served, client(served.ws) as ws:
        ws.send(Start("a", "viseme-lerp", "demo", latency_budget_ms=20.0))
        assert isinstance(ws.recv(), Ready)
        quiet_total, quiet_above = observations_above(
            served, "lipstream_receive_lag_seconds", "0.25"
        )
        assert quiet_total == 1.0 and quiet_above == 0.0  # the start
        held = threading.Event()
        holding = served.call_soon(hold_every_turn(held))
        assert held.wait(30)
        ws.send(Phonemes("a", (PhonemeItem("AA1", 0.0, 0.2),)))
        holding.result(timeout=60)
        answer = ws.recv(timeout=30)
        assert isinstance(answer, Frames)
        total, above = observations_above(served, "lipstream_receive_lag_seconds", "0.25")
        assert (total, above) == (2.0, 1.0)
        frame_total, frame_above = observations_above(served, "lipstream_frame_lag_seconds", "0.25")
        assert frame_total >= 1.0 and frame_above >= 1.0
