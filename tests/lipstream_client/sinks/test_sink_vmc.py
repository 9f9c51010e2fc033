"""VMC messages as a python-osc receiver on loopback gets them: per frame ``OK``, ``T``,
one ``Blend/Val`` per shape, then ``Blend/Apply``."""

from __future__ import annotations

import struct

from pythonosc.osc_bundle import OscBundle

from lipstream_client.sinks import UdpSender
from lipstream_client.sinks.vmc import VmcSink, bundle_datagrams, frame_messages
from tests.helpers import eventually
from tests.lipstream_client.sinks.vmc_receiver import vmc_receiver

FPS = 60.0


def float32(value: float) -> float:
    return float(struct.unpack("<f", struct.pack("<f", value))[0])


def expected_frame(
    names: list[str], index: int, row: list[float]
) -> list[tuple[str, tuple[object, ...]]]:
    return [
        ("/VMC/Ext/OK", (1,)),
        ("/VMC/Ext/T", (float32(index / FPS),)),
        *[("/VMC/Ext/Blend/Val", (name, float32(value))) for name, value in zip(names, row)],
        ("/VMC/Ext/Blend/Apply", ()),
    ]


def test_every_shape_then_apply_once_per_frame() -> None:
    names = ["A", "I", "U", "E", "O", "Blink_L", "Blink_R"]
    rows = [[(i + k) / 20 for k in range(len(names))] for i in range(12)]
    with vmc_receiver() as (port, received):
        sink = VmcSink(UdpSender("127.0.0.1", port))
        sink.open(names, FPS)
        for index, row in enumerate(rows):
            sink.send(index, index / FPS, row)
        eventually(lambda: received.count("/VMC/Ext/Blend/Apply") == len(rows), "every Apply")
        sink.close()
    expected = [message for i, row in enumerate(rows) for message in expected_frame(names, i, row)]
    assert received.messages == expected


def test_52_perfect_sync_shapes_split_across_datagrams_keep_their_order() -> None:
    names = [f"shape{k:02d}WithALongerName" for k in range(52)]
    rows = [[k / 52 for k in range(52)], [1 - k / 52 for k in range(52)]]
    with vmc_receiver() as (port, received):
        sink = VmcSink(UdpSender("127.0.0.1", port), max_datagram=600)
        sink.open(names, FPS)
        for index, row in enumerate(rows):
            sink.send(index, index / FPS, row)
        eventually(lambda: received.count("/VMC/Ext/Blend/Apply") == len(rows), "every Apply")
        datagrams = sink.delivery().sent
        sink.close()
    expected = [message for i, row in enumerate(rows) for message in expected_frame(names, i, row)]
    assert received.messages == expected
    assert datagrams > 2 * len(rows)


def test_bundles_stay_under_the_datagram_size() -> None:
    messages = frame_messages([f"n{k}" for k in range(200)], 0.5, [0.5] * 200)
    datagrams = bundle_datagrams(messages, max_datagram=512)
    assert all(len(datagram) <= 512 for datagram in datagrams)
    unpacked = [content for datagram in datagrams for content in OscBundle(datagram)]
    assert [message.address for message in unpacked] == [m.address for m in messages]
    assert unpacked[-1].address == "/VMC/Ext/Blend/Apply"
