"""The in-process per-message bench streams the same messages to the server's app and the
reference app, and times both."""

from __future__ import annotations

import asyncio
from pathlib import Path

from lipstream.bench.message_cost import compare, leg_events, run_leg, stream_scope
from lipstream.loadtest.clips import synthetic_clip
from lipstream.server.app import create_app
from lipstream_client import Done, Frames, Ready, decode


def test_both_apps_answer_every_leg_and_are_timed(lerp_dir: Path) -> None:
    result = asyncio.run(compare(lerp_dir, "viseme-lerp", "demo", 2, 2, 1.0, 20.0))
    assert result["phonemes_messages"] == len(synthetic_clip(1.0, seed=0)) + len(
        synthetic_clip(1.0, seed=1)
    )
    assert result["fidelity"] == "causal"
    assert len(result["server_us"]) == len(result["reference_us"]) == 2
    assert all(value > 0 for value in result["server_us"] + result["reference_us"])
    # Each request: ready, its frames blocks, done; the reference sends as many messages.
    assert result["messages_sent"]["server"] == result["messages_sent"]["reference"]
    assert result["messages_sent"]["server"] >= 2 * 3


def test_the_first_answer_read_is_the_servers_ready(lerp_dir: Path) -> None:
    async def first_leg() -> list[bytes]:
        app = create_app(lerp_dir)
        async with app.router.lifespan_context(app) as lifespan_state:
            state = dict(lifespan_state or {})
            while state["startup"].server is None:
                await asyncio.sleep(0.05)
            events, _ = leg_events("viseme-lerp", "demo", 1, 1.0, 20.0)
            return await run_leg(app, stream_scope(state), events)

    kinds = [type(decode(payload, "msgpack")) for payload in asyncio.run(first_leg())]
    assert kinds[0] is Ready and kinds[-1] is Done
    assert set(kinds[1:-1]) == {Frames}
