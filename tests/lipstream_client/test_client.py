"""The async and sync clients against a scripted protocol server (tests/lipstream_client/fake_server)."""

from __future__ import annotations

import asyncio
import math
import struct
from collections.abc import Awaitable, Callable, Iterator
from typing import TypeVar

import pytest

from lipstream_client import Done, EncodeError, Encoding, End, Frames, PhonemeItem
from lipstream_client.client import AsyncClient, RequestOver, StreamResult
from lipstream_client.exceptions import (
    ConnectionClosed,
    HandshakeRejected,
    LipstreamServerError,
    ServerBusy,
    ServerGoingAway,
)
from lipstream_client.frame_timeline import FrameTimeline
from lipstream_client.sync import Client
from tests.lipstream_client.fake_server import CHANNELS, FakeServer, expected_row

T = TypeVar("T")
FPS = 50.0
PHONEMES = [("HH", 0.0, 0.1), ("AY", 0.1, 0.3), ("sil", 0.3, 0.42)]


def run(scenario: Callable[[], Awaitable[T]]) -> T:
    async def bounded() -> T:
        return await asyncio.wait_for(scenario(), 10)

    return asyncio.run(bounded())


def float32(value: float) -> float:
    result: float = struct.unpack("<f", struct.pack("<f", value))[0]
    return result


@pytest.fixture
def server() -> Iterator[FakeServer]:
    with FakeServer() as fake:
        yield fake


def expected_rows(last_time: float, offset: float = 0.0) -> list[list[float]]:
    count = math.floor(last_time * FPS + 1e-9) + 1
    return [expected_row(index, offset) for index in range(count)]


async def one_request(url: str, encoding: Encoding, offset: float = 0.0) -> StreamResult:
    async with AsyncClient(url, encoding=encoding) as client:
        stream = await client.start("viseme-lerp", "demo", fps=FPS, options={"offset": offset})
        await stream.send_phonemes(PHONEMES[:2])
        await stream.send_phonemes([{"phoneme": "sil", "start": 0.3, "end": 0.42}])
        await stream.end()
        return await stream.collect()


@pytest.mark.parametrize("encoding", ["msgpack", "json"])
def test_async_request_gets_every_frame_in_order(server: FakeServer, encoding: Encoding) -> None:
    result = run(lambda: one_request(server.url, encoding))
    assert result.ready.channels == CHANNELS and result.ready.fps == FPS
    assert [block.seq for block in result.frames] == list(range(len(result.frames)))
    assert result.frames[0].first_frame == 0
    for previous, block in zip(result.frames, result.frames[1:]):
        assert block.first_frame == previous.end_frame
    assert result.rows() == expected_rows(0.42)
    assert result.done.reason == "end" and result.done.stats.frames == 22


@pytest.mark.parametrize("encoding", ["msgpack", "json"])
def test_sync_and_async_clients_receive_identical_frames(
    server: FakeServer, encoding: Encoding
) -> None:
    from_async = run(lambda: one_request(server.url, encoding, offset=0.125))
    with Client(server.url, encoding, timeout=10) as client:
        assert client.encoding == encoding
        stream = client.start("viseme-lerp", "demo", fps=FPS, options={"offset": 0.125})
        stream.send_phonemes(PHONEMES[:2])
        stream.send_phonemes([PhonemeItem("sil", 0.3, 0.42)])
        stream.end()
        from_sync = stream.collect()
    assert from_sync.frames == from_async.frames
    assert from_sync.done == from_async.done and from_sync.ready == from_async.ready
    assert from_sync.rows() == expected_rows(0.42, 0.125)


def test_multiplexed_requests_each_get_their_own_frames(server: FakeServer) -> None:
    offsets = {"npc-a": 0.25, "npc-b": 0.5, "npc-c": 0.75}
    ends = {"npc-a": 0.2, "npc-b": 0.42, "npc-c": 0.3}

    async def scenario() -> dict[str, StreamResult]:
        async with AsyncClient(server.url) as client:
            streams = {
                name: await client.start(
                    "viseme-lerp", "demo", id=name, fps=FPS, options={"offset": offset}
                )
                for name, offset in offsets.items()
            }
            assert client.active_ids == set(offsets)
            # Interleave the three requests' input on the one connection.
            for step in range(3):
                for name, stream in streams.items():
                    start, end = ends[name] * step / 3, ends[name] * (step + 1) / 3
                    await stream.send_phonemes([("AA", start, end)])
            for stream in streams.values():
                await stream.end()
            results = await asyncio.gather(*(stream.collect() for stream in streams.values()))
            assert client.active_ids == set()
            return dict(zip(streams, results))

    results = run(scenario)
    for name, result in results.items():
        assert all(block.id == name for block in result.frames)
        assert result.rows() == expected_rows(ends[name], offsets[name])


def test_cancel_ends_with_the_frames_sent_so_far(server: FakeServer) -> None:
    async def scenario() -> tuple[list[Frames], Done]:
        async with AsyncClient(server.url) as client:
            stream = await client.start("viseme-lerp", "demo", fps=FPS)
            await stream.send_phonemes([("AA", 0.0, 0.2)])
            await stream.cancel()
            blocks = [block async for block in stream.frames()]
            return blocks, await stream.done()

    blocks, done = run(scenario)
    assert done.reason == "cancel" and done.stats.frames == 10
    assert FrameTimeline(FPS, blocks).rows() == [expected_row(i) for i in range(10)]


def test_interrupt_supersedes_frames_from_the_cut(server: FakeServer) -> None:
    async def scenario() -> StreamResult:
        async with AsyncClient(server.url) as client:
            stream = await client.start("viseme-lerp", "demo", fps=FPS)
            await stream.send_phonemes([("AA", 0.0, 0.4)])
            await stream.interrupt(0.2, return_ms=80)
            return await stream.collect()

    result = run(scenario)
    assert result.done.reason == "interrupt" and result.done.stats.frames == 14
    assert result.frames[0].end_frame == 20  # sent before the interrupt arrived
    assert result.frames[-1].first_frame == 10  # ceil(0.2 * 50), below the 20 already sent
    rows = result.rows()
    assert len(rows) == 14  # frames 14..19 belonged to the speech that was cut off
    assert rows[:10] == [expected_row(i) for i in range(10)]
    face = expected_row(9)
    assert rows[10:14] == [[float32(v * (1 - (k + 1) / 4)) for v in face] for k in range(4)]


def test_fatal_request_error_is_typed_and_spares_other_requests(server: FakeServer) -> None:
    async def scenario() -> tuple[LipstreamServerError, StreamResult]:
        async with AsyncClient(server.url) as client:
            broken = await client.start("missing", "demo", id="bad")
            good = await client.start("viseme-lerp", "demo", fps=FPS)
            with pytest.raises(LipstreamServerError) as from_ready:
                await broken.ready()
            with pytest.raises(LipstreamServerError):
                await broken.done()
            with pytest.raises(LipstreamServerError):
                _ = [block async for block in broken.frames()]
            with pytest.raises(LipstreamServerError):
                await broken.end()
            await good.send_phonemes(PHONEMES)
            await good.end()
            return from_ready.value, await good.collect()

    error, good = run(scenario)
    assert (error.code, error.fatal, error.id) == ("unknown_engine", True, "bad")
    assert "missing" in error.message and not error.retryable
    assert good.rows() == expected_rows(0.42)


def test_busy_server_maps_to_retryable_server_busy() -> None:
    async def scenario() -> ConnectionClosed:
        with FakeServer(busy=True) as busy:
            async with AsyncClient(busy.url) as client:
                closed = await client.wait_closed()
                with pytest.raises(ServerBusy):
                    await client.start("viseme-lerp", "demo")
                return closed

    closed = run(scenario)
    assert isinstance(closed, ServerBusy) and closed.code == 1013 and closed.retryable
    assert closed.error is not None and closed.error.code == "server_busy"


@pytest.mark.parametrize(
    ("character", "kind", "code", "retryable"),
    [
        ("close-1001", ServerGoingAway, 1001, True),
        ("close-1011", ConnectionClosed, 1011, False),
    ],
)
def test_close_codes_end_open_requests(
    server: FakeServer, character: str, kind: type[ConnectionClosed], code: int, retryable: bool
) -> None:
    async def scenario() -> ConnectionClosed:
        async with AsyncClient(server.url) as client:
            stream = await client.start("viseme-lerp", character)
            with pytest.raises(ConnectionClosed) as raised:
                await stream.done()
            return raised.value

    closed = run(scenario)
    assert type(closed) is kind and closed.code == code and closed.retryable is retryable
    if code == 1011:
        assert closed.error is not None and closed.error.code == "internal_error"


def test_token_and_origin_travel_in_the_handshake() -> None:
    with FakeServer(token="s3cret") as guarded:
        ok = run(lambda: one_request_with(guarded.url, token="s3cret", origin="https://a.test"))
        assert ok.rows() == expected_rows(0.42)
        assert guarded.headers[-1]["authorization"] == "Bearer s3cret"
        assert guarded.headers[-1]["origin"] == "https://a.test"
        with pytest.raises(ConnectionClosed) as refused:
            run(lambda: one_request_with(guarded.url, token=None, origin=None))
    assert refused.value.code == 1008 and not refused.value.retryable
    assert refused.value.error is not None and refused.value.error.code == "unauthorized"


async def one_request_with(url: str, token: str | None, origin: str | None) -> StreamResult:
    async with AsyncClient(url, token=token, origin=origin) as client:
        stream = await client.start("viseme-lerp", "demo", fps=FPS)
        await stream.send_phonemes(PHONEMES)
        await stream.end()
        return await stream.collect()


def test_refused_upgrade_is_a_handshake_error() -> None:
    with (
        FakeServer(refuse_upgrade=True) as refusing,
        pytest.raises(HandshakeRejected) as refused,
        Client(refusing.url, timeout=10),
    ):
        pass
    assert refused.value.status == 403 and not refused.value.retryable
    assert "no subprotocol" in refused.value.body


def test_bad_input_is_refused_locally_and_never_sent(server: FakeServer) -> None:
    async def scenario() -> None:
        async with AsyncClient(server.url) as client:
            stream = await client.start("viseme-lerp", "demo", id="x", fps=FPS)
            with pytest.raises(EncodeError) as bad_times:
                await stream.send_phonemes([("AA", 0.3, 0.2)])
            assert bad_times.value.error.code == "invalid_times"
            with pytest.raises(ValueError, match="still open"):
                await client.start("viseme-lerp", "demo", id="x")
            with pytest.raises(ValueError, match="items\\[1\\]"):
                await stream.send_phonemes([("AA", 0.0, 0.1), ["AA", 0.1, 0.2]])  # type: ignore[list-item]  # a list item on purpose: the check under test
            await stream.cancel()
            await stream.done()
            with pytest.raises(RequestOver):
                await stream.end()

    run(scenario)
    assert [type(message).__name__ for message in server.received] == ["Start", "Cancel"]


def test_non_fatal_errors_are_kept_as_warnings(server: FakeServer) -> None:
    async def scenario() -> list[object]:
        async with AsyncClient(server.url, encoding="json") as client:
            await client.send(End("ghost"))
            stream = await client.start("viseme-lerp", "demo", fps=FPS)
            await stream.end()
            await stream.done()
            return list(client.warnings)

    warnings = run(scenario)
    assert len(warnings) == 1
    warning = warnings[0]
    assert isinstance(warning, LipstreamServerError)
    assert (warning.code, warning.id, warning.fatal) == ("unknown_request", "ghost", False)


def test_sync_poll_and_timeouts(server: FakeServer) -> None:
    with Client(server.url, timeout=10) as client:
        stream = client.start("viseme-lerp", "demo", fps=FPS)
        assert stream.ready().channels == CHANNELS
        with pytest.raises(TimeoutError):
            stream.next_block(timeout=0.2)
        assert stream.poll() == []
        stream.send_phonemes([("AA", 0.0, 0.1)])
        first = stream.next_block()
        assert first is not None and first.rows() == [expected_row(i) for i in range(5)]
        stream.end()
        assert stream.done().stats.frames == 6
        late = stream.poll()
        assert [block.first_frame for block in late] == [5]
        assert stream.poll() == [] and stream.next_block() is None


def test_frame_timeline_answers_the_frame_due_at_a_time() -> None:
    timeline = FrameTimeline(60.0)
    assert timeline.at(0.5) is None
    timeline.add(Frames.from_rows("a", 0, 0, 60.0, [[0.0], [1.0], [2.0]]))
    assert timeline.at(1 / 60) == (1, [1.0])
    assert timeline.at(10.0) == (2, [2.0])  # playback ahead of the stream: latest frame
    timeline.add(Frames.from_rows("a", 1, 3, 60.0, [[3.0], [4.0], [5.0]]))
    timeline.add(Frames.from_rows("a", 2, 7, 60.0, [[7.0]]))
    assert timeline.at(6.5 / 60) == (5, [5.0])  # frame 6 missing: the last one before it
    with pytest.raises(ValueError, match=r"\[6\]"):
        timeline.rows()
    # A return-to-rest block from frame 2 rewrites the timeline from there.
    timeline.add(Frames.from_rows("a", 3, 2, 60.0, [[9.0], [8.0]]))
    assert timeline.rows() == [[0.0], [1.0], [9.0], [8.0]]
    timeline.add(Frames.from_rows("a", 4, 4, 60.0, [[6.0]]))
    timeline.truncate(3)
    assert timeline.rows() == [[0.0], [1.0], [9.0]] and len(timeline) == 3
    with pytest.raises(ValueError, match="fps"):
        timeline.add(Frames.from_rows("a", 5, 3, 30.0, [[1.0]]))
    with pytest.raises(ValueError, match="channels"):
        timeline.add(Frames.from_rows("a", 5, 3, 60.0, [[1.0, 2.0]]))
