"""py-spy's raw stacks sorted into the server's layers, and the report block that shows them."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from lipstream.bench.report import Bench, server_profile
from lipstream.bench.server_profile import main

LOOP = "run_forever (asyncio/base_events.py:608);_run_once (asyncio/base_events.py:1922)"
HANDLE = f"{LOOP};_run (asyncio/events.py:84);serve (lipstream/server/websocket.py:290)"
STACKS = [
    f"{LOOP};select (selectors.py:468) 50",
    f"{HANDLE};handle (lipstream/server/session.py:210);stream "
    "(lipstream/engines/anime_graph/streaming.py:40) 7",
    f"{HANDLE};handle (lipstream/server/session.py:210);feed (lipstream/server/request.py:99) 13",
    f"{HANDLE};_send_all (lipstream/server/websocket.py:480);_record "
    "(lipstream/server/websocket.py:546);observe (prometheus_client/metrics.py:600) 3",
    f"{HANDLE};_send_all (lipstream/server/websocket.py:480);write (asyncio/selector_events.py:1) 20",
    f"{HANDLE};_receive (lipstream/server/websocket.py:385);receive (starlette/websockets.py:1) 5",
    f"{LOOP};_read_ready (asyncio/selector_events.py:1) 2",
    "_bootstrap (threading.py:1002);_worker (concurrent/futures/thread.py:81) 9",
    "not a stack line",
]


def test_each_sample_goes_to_the_first_layer_its_stack_matches(tmp_path: Path) -> None:
    stacks = tmp_path / "stacks.txt"
    stacks.write_text("\n".join(STACKS) + "\n", encoding="utf-8")
    results = tmp_path / "bench" / "server_profile.json"
    assert main([str(stacks), "--command", "py-spy record ...", "--results", str(results)]) == 0
    document = json.loads(results.read_text(encoding="utf-8"))
    assert document["samples"] == 109
    samples = {row["layer"]: row["samples"] for row in document["layers"]}
    assert samples == {
        "engine call": 7,
        "metrics": 3,
        "session and request layers": 13,
        "send path": 20,
        "receiving and decoding": 5,
        "event loop polling": 50,
        "other": 2,
        "other threads": 9,
    }
    assert document["top_functions"][0] == {
        "function": "select (selectors.py:468)",
        "samples": 50,
        "share_of_event_loop": 0.5,
    }
    assert document["command"] == "py-spy record ..." and document["date"]
    rendered = server_profile(Bench(results.parent))
    assert "| engine call | 7 | 6.4% | 7.0% |" in rendered
    assert "| event loop polling | 50 | 45.9% | 50.0% |" in rendered
    assert "| other threads | 9 | 8.3% | – |" in rendered


def test_an_empty_profile_has_no_shares(tmp_path: Path) -> None:
    stacks = tmp_path / "stacks.txt"
    stacks.write_text("", encoding="utf-8")
    results = tmp_path / "profile.json"
    main([str(stacks), "--command", "none", "--results", str(results)])
    document = json.loads(results.read_text(encoding="utf-8"))
    assert document["samples"] == 0
    assert all(row["share"] == pytest.approx(0.0) for row in document["layers"])
