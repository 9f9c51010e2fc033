"""The bridge's pacing on an injected clock: each frame at first-arrival + index / fps, a
frame whose successor is already due dropped (not queued) and counted, the speech laid on
the same clock. The stream is a stand-in holding known frames; no wall time is waited."""

from __future__ import annotations

import asyncio
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from lipstream_client import AudioChunk, Done, DoneStats, Frames, Ready
from lipstream_client.bridge import Bridge, BridgeInput, BridgeReport
from lipstream_client.float32 import pack_float32
from lipstream_client.sinks import Delivery

FPS = 50.0
PERIOD = 1 / FPS


class SteppedClock:
    """Time moves only when the bridge sleeps (by exactly that) or a test moves it."""

    def __init__(self) -> None:
        self.time = 100.0

    def now(self) -> float:
        return self.time

    async def sleep(self, seconds: float) -> None:
        assert seconds > 0
        self.time += seconds


@dataclass
class RecordingSink:
    clock: SteppedClock
    sent: list[tuple[int, float, float, list[float]]] = field(default_factory=list)
    channels: tuple[str, ...] = ()

    def open(self, channels: Sequence[str], fps: float) -> None:
        self.channels = tuple(channels)

    def send(self, index: int, time_s: float, row: Sequence[float]) -> None:
        self.sent.append((index, time_s, self.clock.now(), list(row)))

    def delivery(self) -> Delivery:
        return Delivery(len(self.sent))

    def close(self) -> None:
        pass


class KnownStream:
    """A request's messages, given: blocks of frames, speech chunks, done."""

    def __init__(self, blocks: list[Frames], audio: list[AudioChunk], total: int) -> None:
        self.blocks = list(blocks)
        self.audio = audio
        self.warnings: list[Exception] = []
        self.total = total

    async def ready(self) -> Ready:
        return Ready("r1", "viseme-lerp", "demo", FPS, ("jawOpen", "mouthClose"), 0.0, "full")

    async def next_block(self) -> Frames | None:
        return self.blocks.pop(0) if self.blocks else None

    async def done(self) -> Done:
        return Done("r1", DoneStats(frames=self.total))


def block(first: int, rows: list[list[float]]) -> Frames:
    flat = [value for row in rows for value in row]
    return Frames("r1", 0, first, FPS, 2, pack_float32(flat))


ROWS = [[i / 16, 1 - i / 16] for i in range(10)]


def run(bridge: Bridge, stream: KnownStream) -> BridgeReport:
    # KnownStream plays the client's Stream by duck typing: only what _forward reads.
    return asyncio.run(bridge._forward(stream, BridgeInput(text="x")))  # type: ignore[arg-type]


def test_frames_go_out_at_their_due_times_in_order() -> None:
    clock = SteppedClock()
    sink = RecordingSink(clock)
    report = run(Bridge(sink, clock), KnownStream([block(0, ROWS[:4]), block(4, ROWS[4:])], [], 10))
    assert [entry[0] for entry in sink.sent] == list(range(10))
    assert [entry[2] for entry in sink.sent] == pytest.approx(
        [100.0 + i * PERIOD for i in range(10)]
    )
    assert [entry[1] for entry in sink.sent] == pytest.approx([i * PERIOD for i in range(10)])
    assert [entry[3] for entry in sink.sent] == ROWS  # sixteenths: exact in float32
    assert report.sent == 10 and report.dropped == 0 and report.frames == 10


def test_a_frame_whose_successor_is_due_is_dropped_not_queued() -> None:
    clock = SteppedClock()
    sink = RecordingSink(clock)

    def stall(index: int) -> None:
        if index == 2:  # the bridge is held up for 3.5 frame periods after frame 2
            clock.time += 3.5 * PERIOD

    bridge = Bridge(sink, clock, on_frame=stall)
    report = run(bridge, KnownStream([block(0, ROWS)], [], 10))
    # Frame 3 is 2.5 periods late and frame 4 1.5: both dropped. Frame 5 is half a period
    # late, so goes out at once; frame 6 waits for its time again.
    assert [entry[0] for entry in sink.sent] == [0, 1, 2, 5, 6, 7, 8, 9]
    sent_at = {entry[0]: entry[2] - 100.0 for entry in sink.sent}
    assert sent_at[5] == pytest.approx(5.5 * PERIOD) and sent_at[6] == pytest.approx(6 * PERIOD)
    assert report.sent == 8 and report.dropped == 2


def test_the_speech_is_written_on_the_frames_clock(tmp_path: Path) -> None:
    clock = SteppedClock()
    chunks = [
        AudioChunk("r1", 8000, b"\x10\x00" * 800, start=0.0),
        AudioChunk("r1", 8000, b"\x20\x00" * 400, start=0.15),
    ]
    bridge = Bridge(RecordingSink(clock), clock, wav=tmp_path / "speech.wav")
    report = run(bridge, KnownStream([block(0, ROWS)], chunks, 10))
    import wave

    with wave.open(str(tmp_path / "speech.wav"), "rb") as written:
        pcm = written.readframes(written.getnframes())
        assert written.getframerate() == 8000
    assert pcm[: 2 * 800] == b"\x10\x00" * 800
    assert pcm[2 * 800 : 2 * 1200] == bytes(800)  # 0.10 s to 0.15 s: silence
    assert pcm[2 * 1200 :] == b"\x20\x00" * 400
    assert report.speech_s == pytest.approx(0.2)


def test_the_player_hears_the_speech_from_the_first_frame(tmp_path: Path) -> None:
    import sys

    from lipstream_client.sinks import SoundPlayer

    heard = tmp_path / "heard.raw"
    copy = f"import sys; open({str(heard)!r}, 'wb').write(sys.stdin.buffer.read())"
    clock = SteppedClock()
    chunks = [
        AudioChunk("r1", 8000, b"\x10\x00" * 800, start=0.0),
        AudioChunk("r1", 8000, b"\x20\x00" * 400, start=0.15),
    ]
    player = SoundPlayer([sys.executable, "-c", copy, "{rate}"])
    run(
        Bridge(RecordingSink(clock), clock, player=player),
        KnownStream([block(0, ROWS)], chunks, 10),
    )
    assert heard.read_bytes() == b"\x10\x00" * 800 + bytes(800) + b"\x20\x00" * 400
