"""The bridge end to end: a real ``lipstream serve`` on loopback, text in, UDP out, the
receivers on loopback reading what Unreal and a VMC app would read. The bridge's clock is
stepped (it never runs late), so every frame arrives; the expectation is the same
request collected by the SDK, mapped into the packet's slots by the test's own decoder."""

from __future__ import annotations

import asyncio
import io
import socket
import wave
from collections.abc import Iterator
from pathlib import Path

import pytest

from lipstream.corpus import Corpus
from lipstream_client.bridge import Bridge, BridgeInput, BridgeReport
from lipstream_client.sinks import (
    BridgeError,
    LinesSink,
    LiveLinkEncoder,
    LiveLinkSink,
    Sink,
    UdpSender,
)
from lipstream_client.sinks.vmc import VmcSink
from tests.bridge_server import FPS, TEXT, bridge_server, served
from tests.helpers import eventually
from tests.lipstream_client.sinks.livelink_decoder import app_slot, decode
from tests.lipstream_client.sinks.vmc_receiver import vmc_receiver
from tests.lipstream_client.test_bridge_pacing import SteppedClock
from tests.live_server import LiveServer

RECEIVE_TIMEOUT_S = 30.0
# invalid_request before the rig presets came, unknown_retarget since.
SERVER_CODES_FOR_AN_UNKNOWN_PRESET = ("invalid_request", "unknown_retarget")


@pytest.fixture(scope="module")
def server(
    small_demo_corpus: Corpus, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[LiveServer]:
    with bridge_server(small_demo_corpus, tmp_path_factory.mktemp("bridge-models")) as live:
        yield live


def bridge(
    server: LiveServer, sink: Sink, preset: str | None, wav: Path | None = None
) -> BridgeReport:
    runner = Bridge(sink, SteppedClock(), wav=wav)
    request = runner.run(
        server.ws,
        BridgeInput(text=TEXT),
        engine="viseme-lerp",
        character="demo",
        preset=preset,
        fps=FPS,
    )
    try:
        return asyncio.run(request)
    finally:
        sink.close()


def test_a_sink_serves_one_request_after_another(server: LiveServer) -> None:
    expected = served(server.ws, None).rows()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as receiver:
        receiver.bind(("127.0.0.1", 0))
        receiver.settimeout(RECEIVE_TIMEOUT_S)
        sink = LiveLinkSink(UdpSender("127.0.0.1", receiver.getsockname()[1]), LiveLinkEncoder(), 0)
        runner = Bridge(sink, SteppedClock())
        reports = [
            asyncio.run(runner.run(server.ws, BridgeInput(text=TEXT), fps=FPS)) for _ in range(2)
        ]
        packets = [decode(receiver.recv(4096)) for _ in range(2 * len(expected))]
        sink.close()
    assert [report.sent for report in reports] == [len(expected)] * 2
    assert [p.frame_number for p in packets] == list(range(len(expected))) * 2


def test_text_in_live_link_packets_out(server: LiveServer, tmp_path: Path) -> None:
    expected = served(server.ws, "arkit52")
    rows = expected.rows()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as receiver:
        receiver.bind(("127.0.0.1", 0))
        receiver.settimeout(RECEIVE_TIMEOUT_S)
        sink = LiveLinkSink(
            UdpSender("127.0.0.1", receiver.getsockname()[1]), LiveLinkEncoder("Ada"), 1000
        )
        report = bridge(server, sink, "arkit52", wav=tmp_path / "speech.wav")
        packets = [decode(receiver.recv(4096)) for _ in rows]
    assert report.sent == report.frames == len(rows) and report.dropped == 0
    assert len(expected.channels) == 52
    assert [packet.frame_number for packet in packets] == list(range(1000, 1000 + len(rows)))
    for packet, row in zip(packets, rows):
        assert (packet.version, packet.curve_count, packet.subject) == (6, 61, "Ada")
        assert (packet.fps, packet.denominator) == (60, 1)
        curves = [0.0] * 61
        for name, value in zip(expected.channels, row):
            curves[app_slot(name)] = value
        assert list(packet.curves) == curves
    speech = expected.speech_pcm16()
    first = min(chunk.start or 0.0 for chunk in expected.audio)
    with wave.open(str(tmp_path / "speech.wav"), "rb") as written:
        rate = written.getframerate()
        pcm = written.readframes(written.getnframes())
    assert rate == expected.audio[0].sample_rate
    offset = 2 * round(first * rate)
    assert pcm[:offset] == bytes(offset) and pcm[offset:] == speech


def test_text_in_vmc_out_every_shape_then_apply_per_frame(server: LiveServer) -> None:
    expected = served(server.ws, "arkit52")
    rows = expected.rows()
    with vmc_receiver() as (port, received):
        report = bridge(server, VmcSink(UdpSender("127.0.0.1", port)), "arkit52")
        eventually(lambda: received.count("/VMC/Ext/Blend/Apply") == len(rows), "every Apply")
    assert report.sent == len(rows) and report.delivery.refused == 0
    per_frame = 3 + len(expected.channels)
    frames = [
        received.messages[i : i + per_frame] for i in range(0, len(received.messages), per_frame)
    ]
    assert len(frames) == len(rows)
    for index, (messages, row) in enumerate(zip(frames, rows)):
        assert messages[0] == ("/VMC/Ext/OK", (1,))
        assert messages[1][0] == "/VMC/Ext/T" and messages[1][1][0] == pytest.approx(index / FPS)
        assert messages[2:-1] == [
            ("/VMC/Ext/Blend/Val", (name, value)) for name, value in zip(expected.channels, row)
        ]
        assert messages[-1] == ("/VMC/Ext/Blend/Apply", ())


def test_a_receiver_that_is_not_there_is_counted_and_the_bridge_finishes(
    server: LiveServer,
) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    sink = LiveLinkSink(UdpSender("127.0.0.1", port), LiveLinkEncoder())
    report = bridge(server, sink, None)
    assert report.sent == report.frames > 0
    assert report.delivery.refused >= 1


def test_an_unknown_preset_is_the_server_s_coded_error(server: LiveServer) -> None:
    from lipstream_client import LipstreamServerError

    with pytest.raises(LipstreamServerError) as caught:
        bridge(server, LinesSink(io.StringIO()), "no-such-rig")
    assert caught.value.code in SERVER_CODES_FOR_AN_UNKNOWN_PRESET
    assert "'no-such-rig'" in caught.value.message and "arkit52" in caught.value.message


def test_frames_with_no_arkit_channel_cannot_go_to_live_link(server: LiveServer) -> None:
    sink = LiveLinkSink(UdpSender("127.0.0.1", 9), LiveLinkEncoder())
    with pytest.raises(BridgeError) as caught:
        bridge(server, sink, "oculus15")
    assert caught.value.code == "no_livelink_channels"
