"""The real clients against a real ``lipstream serve`` on loopback, with trained models."""

from __future__ import annotations

import asyncio
import math
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from lipstream.engines.base import Model
from lipstream_client import (
    AsyncClient,
    Client,
    Done,
    EncodeError,
    Encoding,
    LipstreamServerError,
    StreamResult,
)
from lipstream_client.rest import RestClient, RestServerError
from tests.helpers import return_frames
from tests.live_server import LiveServer, live_server, save_models

FPS = 60.0
LINE = [
    ("sil", 0.0, 0.1),
    ("HH", 0.1, 0.17),
    ("AH", 0.17, 0.24),
    ("L", 0.24, 0.31),
    ("OW", 0.31, 0.5),
    ("W", 0.5, 0.58),
    ("ER", 0.58, 0.72),
    ("L", 0.72, 0.8),
    ("D", 0.8, 0.86),
    ("sil", 0.86, 1.0),
]
OTHER_LINES = [
    [("sil", 0.0, 0.05), ("M", 0.05, 0.15), ("AA", 0.15, 0.4), ("M", 0.4, 0.5), ("sil", 0.5, 0.7)],
    [("sil", 0.0, 0.2), ("F", 0.2, 0.3), ("UW", 0.3, 0.55), ("sil", 0.55, 0.6)],
]


@pytest.fixture(scope="module")
def served(
    trained_models: dict[str, Model], tmp_path_factory: pytest.TempPathFactory
) -> Iterator[LiveServer]:
    with live_server(save_models(trained_models, tmp_path_factory.mktemp("models"))) as server:
        yield server


def offline(model: Model, spans: list[tuple[str, float, float]]) -> np.ndarray:
    return np.asarray(model.synthesize(spans, fps=FPS).frames, dtype=np.float32)


def streamed(result: StreamResult) -> np.ndarray:
    return np.asarray(result.rows(), dtype=np.float32)


async def request(
    url: str,
    engine: str,
    spans: list[tuple[str, float, float]],
    encoding: Encoding = "msgpack",
    chunk: int = 3,
) -> StreamResult:
    async with AsyncClient(url, encoding=encoding) as client:
        stream = await client.start(engine, "demo", fps=FPS)
        for first in range(0, len(spans), chunk):
            await stream.send_phonemes(spans[first : first + chunk])
        await stream.end()
        return await asyncio.wait_for(stream.collect(), 20)


def test_server_lists_what_it_serves(served: LiveServer, trained_models: dict[str, Model]) -> None:
    rest = RestClient(served.ws)
    assert rest.healthy() and rest.ready()
    characters = rest.characters()
    assert [c.name for c in characters] == ["demo"]
    assert set(characters[0].engines) == set(trained_models)
    assert rest.default_target()[1] == "demo"


@pytest.mark.parametrize("encoding", ["msgpack", "json"])
@pytest.mark.parametrize("engine", ["viseme-lerp", "anime-graph"])
def test_streamed_frames_equal_offline_synthesis(
    served: LiveServer, trained_models: dict[str, Model], engine: str, encoding: Encoding
) -> None:
    result = asyncio.run(request(served.ws, engine, LINE, encoding))
    model = trained_models[engine]
    assert result.ready.channels == tuple(model.channels)
    assert result.done.reason == "end"
    expected = offline(model, LINE)
    assert result.done.stats.frames == len(expected) + return_frames(FPS)
    np.testing.assert_array_equal(streamed(result)[: len(expected)], expected)


def test_sync_and_async_clients_get_identical_frames(served: LiveServer) -> None:
    from_async = asyncio.run(request(served.ws, "viseme-lerp", LINE))
    with Client(served.ws, timeout=20) as client:
        stream = client.start("viseme-lerp", "demo", fps=FPS)
        for first in range(0, len(LINE), 3):
            stream.send_phonemes(LINE[first : first + 3])
        stream.end()
        from_sync = stream.collect()
    np.testing.assert_array_equal(streamed(from_sync), streamed(from_async))
    assert from_sync.ready == from_async.ready
    assert from_sync.done.stats.frames == from_async.done.stats.frames


def test_multiplexed_requests_each_get_their_own_frames(
    served: LiveServer, trained_models: dict[str, Model]
) -> None:
    lines = {"npc-1": LINE, "npc-2": OTHER_LINES[0], "npc-3": OTHER_LINES[1]}

    async def scenario() -> dict[str, StreamResult]:
        async with AsyncClient(served.ws) as client:
            streams = {
                name: await client.start("viseme-lerp", "demo", id=name, fps=FPS) for name in lines
            }
            for step in range(max(map(len, lines.values()))):
                for name, stream in streams.items():
                    if step < len(lines[name]):
                        await stream.send_phonemes([lines[name][step]])
            for stream in streams.values():
                await stream.end()
            results = await asyncio.wait_for(
                asyncio.gather(*(stream.collect() for stream in streams.values())), 20
            )
            return dict(zip(streams, results))

    results = asyncio.run(scenario())
    model = trained_models["viseme-lerp"]
    for name, result in results.items():
        assert {block.id for block in result.frames} == {name}
        expected = offline(model, lines[name])
        assert len(streamed(result)) == len(expected) + return_frames(FPS)
        np.testing.assert_array_equal(streamed(result)[: len(expected)], expected)


def test_cancel_and_interrupt(served: LiveServer, trained_models: dict[str, Model]) -> None:
    at = 0.5

    async def scenario() -> tuple[Done, StreamResult]:
        async with AsyncClient(served.ws) as client:
            cancelled = await client.start("viseme-lerp", "demo", fps=FPS)
            await cancelled.send_phonemes(LINE[:4])
            await cancelled.cancel()
            cancel_done = await asyncio.wait_for(cancelled.done(), 20)
            cut = await client.start("viseme-lerp", "demo", fps=FPS)
            await cut.send_phonemes(LINE)
            await cut.interrupt(at, return_ms=100)
            return cancel_done, await asyncio.wait_for(cut.collect(), 20)

    cancel_done, interrupted = asyncio.run(scenario())
    assert cancel_done.reason == "cancel"
    assert interrupted.done.reason == "interrupt"
    cut_index = math.ceil(at * FPS - 1e-9)
    assert any(block.first_frame == cut_index for block in interrupted.frames)
    rows = streamed(interrupted)
    expected = offline(trained_models["viseme-lerp"], LINE)
    np.testing.assert_array_equal(rows[:cut_index], expected[:cut_index])
    assert interrupted.done.stats.frames == len(rows) > cut_index


def test_errors_are_typed_and_the_connection_keeps_serving(served: LiveServer) -> None:
    async def scenario() -> tuple[LipstreamServerError, LipstreamServerError, StreamResult]:
        async with AsyncClient(served.ws) as client:
            no_engine = await client.start("no-such-engine", "demo", fps=FPS)
            with pytest.raises(LipstreamServerError) as engine_error:
                await asyncio.wait_for(no_engine.done(), 20)
            bad_label = await client.start("viseme-lerp", "demo", fps=FPS)
            await bad_label.send_phonemes([("sil", 0.0, 0.1), ("QQQ", 0.1, 0.2)])
            with pytest.raises(LipstreamServerError) as phoneme_error:
                await asyncio.wait_for(bad_label.done(), 20)
            good = await client.start("viseme-lerp", "demo", fps=FPS)
            await good.send_phonemes(LINE)
            await good.end()
            return (
                engine_error.value,
                phoneme_error.value,
                await asyncio.wait_for(good.collect(), 20),
            )

    engine_error, phoneme_error, good = asyncio.run(scenario())
    assert (engine_error.code, engine_error.fatal) == ("unknown_engine", True)
    assert (phoneme_error.code, phoneme_error.fatal) == ("unknown_phoneme", True)
    assert "QQQ" in phoneme_error.message
    assert good.done.reason == "end" and len(good.rows()) == good.done.stats.frames


def test_loadtest_against_the_real_server(served: LiveServer, tmp_path: Path) -> None:
    from lipstream.loadtest.load import LoadTestConfig, loadtest

    results = loadtest(
        LoadTestConfig(
            url=served.ws, streams=2, requests=2, clips_s=(1.0,), pause_s=0.0, max_duration_s=30.0
        )
    )
    clip = results["clips"][0]
    assert clip["successful_requests"] == 2, clip["errors"]
    assert results["config"]["character"] == "demo"
    assert clip["frames"] == 2 * (math.floor(1.0 * 60) + 1 + return_frames(60))
    latency = clip["first_packet_latency_ms"]
    # measured from each request's start to its first packet, within the run
    assert 0 < latency["p50"] <= latency["max"] < 1000.0 * clip["wall_s"]
    assert clip["frame_lag_ms"]["p99"] is not None


@pytest.mark.parametrize("encoding", ["msgpack", "json"])
def test_rest_synthesize_equals_the_stream(served: LiveServer, encoding: Encoding) -> None:
    rest = RestClient(served.ws, encoding=encoding)
    answer = rest.synthesize("viseme-lerp", "demo", LINE, fps=FPS)
    stream = asyncio.run(request(served.ws, "viseme-lerp", LINE))
    assert answer.channels == stream.channels and answer.ready.fps == FPS
    assert answer.stats.frames == stream.done.stats.frames == answer.frames.n_frames
    np.testing.assert_array_equal(np.asarray(answer.rows(), dtype=np.float32), streamed(stream))


def test_rest_synthesize_errors_are_typed(served: LiveServer) -> None:
    rest = RestClient(served.ws)
    with pytest.raises(RestServerError) as no_engine:
        rest.synthesize("no-such-engine", "demo", LINE)
    assert (no_engine.value.status, no_engine.value.code) == (404, "unknown_engine")
    with pytest.raises(RestServerError) as bad_label:
        RestClient(served.ws, encoding="json").synthesize(
            "viseme-lerp", "demo", [("QQQ", 0.0, 0.1)]
        )
    assert bad_label.value.code == "unknown_phoneme" and bad_label.value.status >= 400
    with pytest.raises(EncodeError):  # refused before sending
        rest.synthesize("viseme-lerp", "demo", [("AA", 0.2, 0.1)])
