"""Live Link Face packets, read back by a decoder written from the published layout
(PyLiveLinkFace's, which was written from the app's own packets), and compared byte for
byte with a packet PyLiveLinkFace's own encoder made (data/README.md)."""

from __future__ import annotations

import socket
import struct
from datetime import datetime
from pathlib import Path

import pytest

from lipstream.corpus.livelink import ARKIT_BLENDSHAPES
from lipstream_client.sinks import BridgeError, LiveLinkEncoder, LiveLinkSink, UdpSender
from lipstream_client.sinks.livelink import (
    LIVELINK_BLENDSHAPES,
    LIVELINK_CURVES,
    LiveLinkLayout,
    encode_packet,
    frame_rate,
    frames_since_midnight,
)
from tests.lipstream_client.sinks.livelink_decoder import APP_CURVES, app_slot, decode

GOLDEN = Path(__file__).parent / "data" / "pylivelinkface-0.1-packet.bin"


def test_the_encoder_makes_pylivelinkface_s_packet_byte_for_byte() -> None:
    golden = GOLDEN.read_bytes()
    read = decode(golden)
    assert read.version == 6 and read.curve_count == 61 and read.subject == "lipstream"
    assert read.device_id == "$12345678-9abc-4def-8123-456789abcdef"
    assert (read.fps, read.denominator) == (60, 1)
    assert read.curves == tuple(
        [(i + 1) / 64 for i in range(52)] + [-(i + 1) / 16 for i in range(9)]
    )
    ours = encode_packet(
        read.device_id, read.subject, read.frame_number, read.sub_frame, (60, 1), read.curves
    )
    assert ours == golden


def test_unreal_s_reading_of_the_same_bytes_is_a_version_byte_and_a_36_char_id() -> None:
    packet = encode_packet("$" + "0" * 36, "face", 7, 0.0, (60, 1), [0.0] * 61)
    assert packet[0] == 6
    assert struct.unpack_from(">i", packet, 1) == (36,)
    assert packet[5:41] == b"0" * 36


def test_the_curves_are_in_the_app_s_order_not_the_csv_s() -> None:
    assert [name[:1].upper() + name[1:] for name in LIVELINK_CURVES] == APP_CURVES
    assert set(LIVELINK_BLENDSHAPES) == set(ARKIT_BLENDSHAPES)
    # The app's CSV exports swap these two pairs; the packet does not.
    assert ARKIT_BLENDSHAPES.index("jawRight") < ARKIT_BLENDSHAPES.index("jawLeft")
    assert (app_slot("jawLeft"), app_slot("jawRight")) == (15, 16)
    assert (app_slot("mouthLeft"), app_slot("mouthRight")) == (21, 22)


def test_channels_land_in_their_slots_by_name_in_any_naming_and_the_rest_stay_at_rest() -> None:
    channels = ["JawOpen", "mouthLeft", "eyeBlink_L", "viseme_aa", "headYaw"]
    layout = LiveLinkLayout.for_channels(channels)
    assert layout.unmatched == ("viseme_aa",)
    curves = layout.curves([0.5, 0.25, 0.75, 0.9, -0.125])
    expected = [0.0] * 61
    expected[app_slot("jawOpen")] = 0.5
    expected[app_slot("mouthLeft")] = 0.25
    expected[app_slot("eyeBlinkLeft")] = 0.75
    expected[app_slot("headYaw")] = -0.125
    assert curves == expected


def test_frames_without_an_arkit_curve_are_a_coded_error() -> None:
    with pytest.raises(BridgeError) as caught:
        LiveLinkLayout.for_channels(["viseme_sil", "viseme_PP"])
    assert caught.value.code == "no_livelink_channels" and caught.value.where == "--preset"


@pytest.mark.parametrize(
    ("fps", "rate"), [(60.0, (60, 1)), (30000 / 1001, (30000, 1001)), (29.97, (2997, 100))]
)
def test_frame_rates_are_a_ratio_of_integers(fps: float, rate: tuple[int, int]) -> None:
    assert frame_rate(fps) == rate


def test_the_first_frame_number_is_the_time_of_day_in_frames() -> None:
    noon = datetime(2026, 1, 2, 12, 0, 0, 500000)
    assert frames_since_midnight(noon, (60, 1)) == 12 * 3600 * 60 + 30
    assert frames_since_midnight(noon, (30000, 1001)) == (12 * 3600 * 2 + 1) * 30000 // 2002


def test_a_bad_subject_or_device_id_is_refused() -> None:
    with pytest.raises(BridgeError) as caught:
        LiveLinkEncoder("x" * 300)
    assert caught.value.code == "invalid_subject"
    with pytest.raises(ValueError, match="36-character"):
        encode_packet("$short", "face", 0, 0.0, (60, 1), [0.0] * 61)


def test_the_sink_sends_one_packet_per_frame_numbered_in_order() -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as receiver:
        receiver.bind(("127.0.0.1", 0))
        receiver.settimeout(10)
        port = receiver.getsockname()[1]
        sink = LiveLinkSink(UdpSender("127.0.0.1", port), LiveLinkEncoder("Ada"), 5000)
        sink.open(["jawOpen", "mouthClose"], 60.0)
        rows = [[0.125 * i, 1.0 - 0.125 * i] for i in range(6)]
        for index, row in enumerate(rows):
            sink.send(index, index / 60.0, row)
        packets = [decode(receiver.recv(2048)) for _ in rows]
        sink.close()
    assert [packet.frame_number for packet in packets] == list(range(5000, 5006))
    assert {packet.subject for packet in packets} == {"Ada"}
    assert len({packet.device_id for packet in packets}) == 1
    for packet, row in zip(packets, rows):
        assert packet.curves[app_slot("jawOpen")] == row[0]
        assert packet.curves[app_slot("mouthClose")] == row[1]
        assert sum(1 for value in packet.curves if value != 0.0) <= 2
    assert sink.delivery().sent == 6


def test_a_subject_is_the_same_device_run_after_run() -> None:
    first, again, other = LiveLinkEncoder("Ada"), LiveLinkEncoder("Ada"), LiveLinkEncoder("Bo")
    assert first.device_id == again.device_id != other.device_id
    assert first.device_id.startswith("$") and len(first.device_id) == 37


def test_each_request_numbers_from_the_time_of_day_it_opens() -> None:
    times = iter([datetime(2026, 1, 2, 0, 0, 1), datetime(2026, 1, 2, 0, 0, 3)])
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as receiver:
        receiver.bind(("127.0.0.1", 0))
        receiver.settimeout(10)
        sender = UdpSender("127.0.0.1", receiver.getsockname()[1])
        sink = LiveLinkSink(sender, LiveLinkEncoder(), wall_clock=lambda: next(times))
        numbers = []
        for _ in range(2):
            sink.open(["jawOpen"], 60.0)
            sink.send(0, 0.0, [0.5])
            sink.send(1, 1 / 60, [0.5])
            numbers += [decode(receiver.recv(2048)).frame_number for _ in range(2)]
        sink.close()
    assert numbers == [60, 61, 180, 181]
