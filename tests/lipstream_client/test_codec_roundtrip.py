"""Round trips of every message through both encodings, and exact wire forms."""

from __future__ import annotations

import base64
import json
import struct

import msgpack
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lipstream_client import (
    AudioChunk,
    Cancel,
    ChannelTransform,
    Done,
    DoneStats,
    Encoding,
    End,
    ErrorMessage,
    Frames,
    Interrupt,
    Message,
    OutputProfile,
    PhonemeItem,
    Phonemes,
    ProtocolError,
    Ready,
    Start,
    decode,
    encode,
)
from lipstream_client.codec import (
    SUBPROTOCOL_JSON,
    SUBPROTOCOL_MSGPACK,
    encoding_for_subprotocol,
    select_subprotocol,
    subprotocol_for,
)
from lipstream_client.messages import CLIENT_MESSAGE_TYPES, MESSAGE_TYPES, SERVER_MESSAGE_TYPES
from tests.lipstream_client.strategies import (
    audio_chunks,
    cancels,
    dones,
    ends,
    error_messages,
    frames_messages,
    interrupts,
    messages,
    phonemes_messages,
    readies,
    starts,
    texts,
    words_messages,
)

ENCODINGS: tuple[Encoding, ...] = ("msgpack", "json")
PER_TYPE: dict[str, st.SearchStrategy[Message]] = {
    "start": starts(),
    "phonemes": phonemes_messages,
    "audio": audio_chunks,
    "text": texts,
    "words": words_messages,
    "end": ends,
    "cancel": cancels,
    "interrupt": interrupts,
    "ready": readies,
    "frames": frames_messages(),
    "done": dones,
    "error": error_messages,
}


def test_every_message_type_has_a_strategy() -> None:
    assert set(PER_TYPE) == set(MESSAGE_TYPES)
    assert set(CLIENT_MESSAGE_TYPES) == {
        "start",
        "phonemes",
        "audio",
        "text",
        "words",
        "end",
        "cancel",
        "interrupt",
    }
    assert set(SERVER_MESSAGE_TYPES) == {"ready", "frames", "audio", "done", "error"}


@pytest.mark.parametrize("message_type", sorted(PER_TYPE))
@pytest.mark.parametrize("encoding", ENCODINGS)
@settings(max_examples=40, deadline=None)
@given(data=st.data())
def test_round_trip_is_identity(message_type: str, encoding: Encoding, data: st.DataObject) -> None:
    message = data.draw(PER_TYPE[message_type])
    wire = encode(message, encoding)
    assert isinstance(wire, bytes if encoding == "msgpack" else str)
    decoded = decode(wire, encoding)
    assert decoded == message
    assert not isinstance(decoded, ProtocolError)
    assert encode(decoded, encoding) == wire


@settings(max_examples=60, deadline=None)
@given(message=messages())
def test_both_encodings_decode_to_the_same_message(message: Message) -> None:
    assert decode(encode(message, "msgpack"), "msgpack") == decode(encode(message, "json"), "json")


def test_start_json_wire_form_is_exact() -> None:
    message = Start(
        "r1",
        "dp",
        "ada",
        fps=30.0,
        emotion="happy",
        latency_budget_ms=120.0,
        output=OutputProfile(
            naming="livelink",
            channels=("JawOpen",),
            transforms={"JawOpen": ChannelTransform(1.5, 0.0, (0.0, 1.0))},
        ),
        options={"lag": 4},
    )
    assert json.loads(encode(message, "json")) == {
        "v": 1,
        "type": "start",
        "id": "r1",
        "engine": "dp",
        "character": "ada",
        "fps": 30.0,
        "output": {
            "naming": "livelink",
            "channels": ["JawOpen"],
            "transforms": {"JawOpen": {"multiplier": 1.5, "offset": 0.0, "clamp": [0.0, 1.0]}},
        },
        "emotion": "happy",
        "latency_budget_ms": 120.0,
        "options": {"lag": 4},
    }


def test_optional_fields_are_omitted_and_error_id_is_always_present() -> None:
    assert json.loads(encode(End("a"), "json")) == {"v": 1, "type": "end", "id": "a"}
    assert json.loads(encode(Interrupt("a", 1.25), "json")) == {
        "v": 1,
        "type": "interrupt",
        "id": "a",
        "at": 1.25,
    }
    assert json.loads(encode(ErrorMessage("server_busy", "full", None, True), "json")) == {
        "v": 1,
        "type": "error",
        "code": "server_busy",
        "message": "full",
        "id": None,
        "fatal": True,
    }


def test_absent_and_null_optional_fields_decode_alike() -> None:
    base = {"v": 1, "type": "start", "id": "a", "engine": "dp", "character": "ada"}
    with_nulls = {
        **base,
        "fps": None,
        "channels": None,
        "output": None,
        "emotion": None,
        "latency_budget_ms": None,
        "options": None,
    }
    expected = Start("a", "dp", "ada", fps=60.0)
    assert decode(json.dumps(base), "json") == expected
    assert decode(json.dumps(with_nulls), "json") == expected


def test_frames_msgpack_data_is_float32_little_endian_bin() -> None:
    message = Frames.from_rows("a", 3, 120, 60.0, [[0.5, -1.0], [0.25, 2.0]])
    payload = msgpack.unpackb(encode(message, "msgpack"), raw=False)
    assert payload["data"] == struct.pack("<4f", 0.5, -1.0, 0.25, 2.0)
    assert payload["data"] == bytes.fromhex("0000003f000080bf0000803e00000040")
    assert (payload["seq"], payload["first_frame"], payload["n_channels"]) == (3, 120, 2)


def test_frames_json_data_is_nested_rows_of_shortest_float32_decimals() -> None:
    message = Frames.from_rows("a", 0, 0, 60.0, [[0.1, 1 / 3], [-0.0, 3.4028234663852886e38]])
    payload = json.loads(encode(message, "json"))
    assert payload["data"] == [[0.1, 0.33333334], [-0.0, 3.4028235e38]]
    assert decode(encode(message, "json"), "json") == message


def test_frames_helpers_give_rows_times_and_shape() -> None:
    message = Frames.from_rows("a", 0, 6, 30.0, [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])
    assert (message.n_frames, message.n_channels, message.end_frame) == (2, 3, 8)
    assert message.rows() == [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]
    assert message.times() == [0.2, 7 / 30]
    with pytest.raises(ValueError, match="every row"):
        Frames.from_rows("a", 0, 0, 30.0, [[1.0], [1.0, 2.0]])


def test_audio_is_bin_in_msgpack_and_base64_in_json() -> None:
    chunk = AudioChunk.from_samples("a", 16000, [0, 1, -1, 32767, -32768])
    assert chunk.pcm16 == bytes.fromhex("00000100ffffff7f0080")
    assert chunk.samples() == [0, 1, -1, 32767, -32768]
    assert chunk.duration == 5 / 16000
    assert msgpack.unpackb(encode(chunk, "msgpack"), raw=False)["pcm16"] == chunk.pcm16
    assert json.loads(encode(chunk, "json"))["pcm16"] == base64.b64encode(chunk.pcm16).decode()


def test_done_and_ready_round_trip_with_all_fields() -> None:
    stats = DoneStats(90, 12.5, 30.0, True, {"jumps": 3, "cost": 1.5}, speech_synthesis_ms=150.25)
    done = Done("a", stats, "interrupt")
    ready = Ready(
        "a",
        "dp",
        "ada",
        60.0,
        ("jawOpen", "mouthClose"),
        83.3,
        "fixed_lag",
        emotion="sad",
        latency_budget_ms=100.0,
        options={"lag": 5},
    )
    phonemes = Phonemes("a", (PhonemeItem("HH", 0.0, 0.1), PhonemeItem("AY", 0.1, 0.3, "happy")))
    for message in (done, ready, phonemes, Cancel("a")):
        for encoding in ENCODINGS:
            assert decode(encode(message, encoding), encoding) == message


def test_subprotocol_names_select_encodings() -> None:
    assert (SUBPROTOCOL_MSGPACK, SUBPROTOCOL_JSON) == ("lipstream.v1.msgpack", "lipstream.v1.json")
    assert encoding_for_subprotocol("lipstream.v1.json") == "json"
    assert encoding_for_subprotocol("lipstream.v1.msgpack") == "msgpack"
    assert encoding_for_subprotocol(None) == "msgpack"
    assert encoding_for_subprotocol("lipstream.v2.json") is None
    assert subprotocol_for("json") == "lipstream.v1.json"
    assert (
        select_subprotocol(["chat", "lipstream.v1.json", "lipstream.v1.msgpack"])
        == "lipstream.v1.json"
    )
    assert select_subprotocol(["lipstream.v2.msgpack"]) is None
    with pytest.raises(ValueError, match="encoding"):
        subprotocol_for("xml")  # type: ignore[arg-type]  # an unknown encoding on purpose
