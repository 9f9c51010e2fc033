"""The reference server sends what the engine sends, message for message, with no synthesis."""

from __future__ import annotations

import asyncio
from collections.abc import Iterator
from pathlib import Path

import pytest

from lipstream.config import ServerSettings
from lipstream.engines.base import Model, frame_count
from lipstream.loadtest.load import LoadTestConfig, loadtest
from lipstream.loadtest.reference import (
    ReferenceTraffic,
    engine_traffic,
    reference_server,
    with_retries,
)
from lipstream_client.client import AsyncClient
from lipstream_client.exceptions import HandshakeRejected
from tests.lipstream.server.harness import Served, serving

FPS = 60.0
# viseme-lerp's causal rung at a fixed calibration (tests/lipstream/server/test_causal_serving)
CAUSAL_BUDGET_MS = 20.0
SPANS = [("sil", 0.0, 0.05), ("B", 0.05, 0.11), ("AA1", 0.11, 0.3), ("M", 0.3, 0.38)]
WAIT_S = 10.0
RETURN_FRAMES = 9  # the server's default return to rest after end: 150 ms at 60 fps
Block = tuple[int, int, int]  # first frame, frames, data bytes


@pytest.fixture(scope="module")
def served(trained_models: dict[str, Model], tmp_path: Path) -> Iterator[Served]:
    trained_models["viseme-lerp"].save(tmp_path / "viseme-lerp")
    with serving(tmp_path, ServerSettings()) as running:  # at the fixed calibration
        yield running


@pytest.fixture(scope="module")
def tmp_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("reference-models")


async def _blocks_per_message(url: str) -> list[list[Block]]:
    """The frames blocks that answer each phonemes message (read until the frames its input
    covers have come), then those that answer ``end``."""
    answers: list[list[Block]] = []
    async with AsyncClient(url, "msgpack") as client:
        stream = await client.start(
            "viseme-lerp", "demo", fps=FPS, latency_budget_ms=CAUSAL_BUDGET_MS
        )
        received = 0
        for span in SPANS:
            await stream.send_phonemes([span])
            answer: list[Block] = []
            while received < frame_count(span[2], FPS):
                block = await asyncio.wait_for(stream.next_block(), WAIT_S)
                assert block is not None
                answer.append((block.first_frame, block.n_frames, len(block.data)))
                received += block.n_frames
            answers.append(answer)
        await stream.end()
        rest: list[Block] = []
        while (block := await asyncio.wait_for(stream.next_block(), WAIT_S)) is not None:
            rest.append((block.first_frame, block.n_frames, len(block.data)))
        answers.append(rest)
    return answers


def test_the_reference_sends_the_engines_messages_of_the_same_sizes_at_the_same_times(
    served: Served,
) -> None:
    traffic = engine_traffic(served.ws, "viseme-lerp", "demo", FPS, CAUSAL_BUDGET_MS)
    assert traffic.fidelity == "causal" and traffic.lookahead_ms == 0.0
    width = len(traffic.channels)
    # Independently: a causal rung releases frames i / fps <= end as each span arrives, so
    # end sends only the return to rest (150 ms at 60 fps: 9 frames); float32 rows of the
    # channels' width.
    cuts = [0] + [frame_count(end, FPS) for _, _, end in SPANS]
    cuts.append(cuts[-1] + RETURN_FRAMES)
    expected = [
        [(first, last - first, (last - first) * width * 4)] if last > first else []
        for first, last in zip(cuts, cuts[1:])
    ]
    with reference_server(traffic) as url:
        assert asyncio.run(_blocks_per_message(url)) == expected
    assert asyncio.run(_blocks_per_message(served.ws)) == expected


def test_a_load_test_of_the_reference_gets_every_frame_of_every_request() -> None:
    traffic = ReferenceTraffic(("jawOpen", "mouthClose", "mouthFunnel"), 0.0, "causal")
    with reference_server(traffic, workers=2) as url:
        config = LoadTestConfig(
            url=url,
            streams=2,
            requests=2,
            clips_s=(1.0,),
            fps=FPS,
            engine="viseme-lerp",
            character="demo",
            pause_s=0.0,
            max_duration_s=30.0,
        )
        results = loadtest(config)
    clip = results["clips"][0]
    assert clip["successful_requests"] == 2 and clip["errors"] == {}
    assert clip["frames"] == 2 * (frame_count(1.0, FPS) + RETURN_FRAMES)
    # The reference's processes are found by their port: a supervisor and two workers.
    assert results["summary"]["server_processes"] == 3


BUSY_BODY = (
    '{"error":{"code":"server_busy","message":"busy","details":{"retry_after_ms":1129,'
    '"reason":"loop_busy"}}}'
)


def test_learning_the_traffic_waits_out_a_busy_server_as_it_asks() -> None:
    failures = [HandshakeRejected(503, BUSY_BODY), HandshakeRejected(503, "", retry_after="2")]
    waits: list[float] = []

    async def attempt() -> str:
        if failures:
            raise failures.pop(0)
        return "ready"

    async def sleep(seconds: float) -> None:
        waits.append(seconds)

    assert asyncio.run(with_retries(attempt, attempts=3, sleep=sleep)) == "ready"
    assert waits == [1.129, 2.0]  # details.retry_after_ms, then the Retry-After header


def test_learning_the_traffic_gives_up_after_its_attempts_and_on_a_lasting_refusal() -> None:
    tries = 0

    async def busy() -> str:
        nonlocal tries
        tries += 1
        raise HandshakeRejected(503, BUSY_BODY)

    async def sleep(seconds: float) -> None:
        pass

    with pytest.raises(HandshakeRejected):
        asyncio.run(with_retries(busy, attempts=4, sleep=sleep))
    assert tries == 4
    tries = 0

    async def forbidden() -> str:
        nonlocal tries
        tries += 1
        raise HandshakeRejected(403, "")

    with pytest.raises(HandshakeRejected):
        asyncio.run(with_retries(forbidden, attempts=4, sleep=sleep))
    assert tries == 1
