"""Specific bad inputs map to specific, documented error codes; encode refuses what decode rejects."""

from __future__ import annotations

import json
import math
import struct
from typing import Any

import msgpack
import pytest

from lipstream_client import (
    Done,
    EncodeError,
    End,
    ErrorMessage,
    Frames,
    PhonemeItem,
    Phonemes,
    ProtocolError,
    Start,
    decode,
    encode,
)
from lipstream_client import errors as codes

START = {"v": 1, "type": "start", "id": "r1", "engine": "dp", "character": "ada"}
PHONEMES = {
    "v": 1,
    "type": "phonemes",
    "id": "r1",
    "items": [
        {"phoneme": "HH", "start": 0.0, "end": 0.1},
        {"phoneme": "AY", "start": 0.1, "end": 0.3},
    ],
}
FRAMES = {
    "v": 1,
    "type": "frames",
    "id": "r1",
    "seq": 0,
    "first_frame": 0,
    "fps": 60.0,
    "n_channels": 2,
    "data": [[0.0, 1.0], [0.5, 0.25]],
}


def with_field(base: dict[str, Any], path: str, value: Any) -> dict[str, Any]:
    """A deep copy of ``base`` with the dotted ``path`` (list indices as numbers) set."""
    copy: dict[str, Any] = json.loads(json.dumps(base))
    *parents, last = path.split(".")
    node: Any = copy
    for key in parents:
        node = node[int(key)] if isinstance(node, list) else node[key]
    if isinstance(node, list):
        node[int(last)] = value
    else:
        node[last] = value
    return copy


def rejected_json(payload: Any) -> ProtocolError:
    result = decode(json.dumps(payload), "json")
    assert isinstance(result, ProtocolError), result
    return result


def rejected_msgpack(data: bytes) -> ProtocolError:
    result = decode(data, "msgpack")
    assert isinstance(result, ProtocolError), result
    return result


@pytest.mark.parametrize(
    "data",
    [
        b"\xc1",  # reserved, never valid
        msgpack.packb({"v": 1}) + b"\x00",  # trailing bytes
        msgpack.packb(msgpack.ExtType(42, b"payload")),  # ext types are refused
        b"\xd6\xff\x00\x00\x00\x01",  # timestamp ext
        msgpack.packb({1: 2}),  # non-string key
        msgpack.packb({b"v": 1}, use_bin_type=True),  # binary key
        b"\x82\xa1v\x01\xa1v\x01",  # duplicate key
        b"\xa2\xff\xfe",  # invalid UTF-8 string
        b"\x91" * 5000 + b"\xc0",  # nesting bomb
        b"\xdd\xff\xff\xff\xff",  # array header claiming 4G items
        b"",
    ],
)
def test_undecodable_msgpack_is_malformed_and_not_fatal(data: bytes) -> None:
    error = rejected_msgpack(data)
    assert (error.code, error.id, error.fatal) == (codes.MALFORMED, None, False)


@pytest.mark.parametrize(
    "text",
    [
        "{",
        '{"v": 1,}',
        "NaN",
        '{"v": NaN}',
        '{"v": Infinity}',
        "\ufeff{}",
        '{"id": "a", "id": "b"}',
        "[" * 100_000 + "]" * 100_000,
        "1" * 5000,
        "",
    ],
)
def test_undecodable_json_is_malformed(text: str) -> None:
    error = decode(text, "json")
    assert isinstance(error, ProtocolError)
    assert error.code == codes.MALFORMED


def test_wrong_frame_kind_and_bad_utf8_are_malformed() -> None:
    assert rejected_msgpack(b'{"v":1}').code == codes.MALFORMED
    text_under_msgpack = decode('{"v": 1}', "msgpack")
    assert isinstance(text_under_msgpack, ProtocolError)
    assert text_under_msgpack.code == codes.MALFORMED
    bad_utf8 = decode(b'{"v": "\xff"}', "json")
    assert isinstance(bad_utf8, ProtocolError) and bad_utf8.code == codes.MALFORMED
    assert decode(b'{"v":1,"type":"end","id":"a"}', "json") == End("a")


@pytest.mark.parametrize("payload", [[1, 2], "start", None, 3.5, True])
def test_non_object_payload_is_invalid_message(payload: Any) -> None:
    error = rejected_json(payload)
    assert (error.code, error.id, error.fatal) == (codes.INVALID_MESSAGE, None, False)


@pytest.mark.parametrize(
    ("version", "code"),
    [
        (2, codes.UNSUPPORTED_VERSION),
        (0, codes.UNSUPPORTED_VERSION),
        (1.5, codes.UNSUPPORTED_VERSION),
        ("1", codes.INVALID_MESSAGE),
        (True, codes.INVALID_MESSAGE),
        (None, codes.INVALID_MESSAGE),
    ],
)
def test_version_field(version: Any, code: str) -> None:
    error = rejected_json({**START, "v": version})
    assert (error.code, error.where, error.id, error.fatal) == (code, "v", "r1", True)


def test_missing_version_and_type() -> None:
    no_version = {key: value for key, value in START.items() if key != "v"}
    assert rejected_json(no_version).code == codes.INVALID_MESSAGE
    assert "'v'" in rejected_json(no_version).message
    no_type = {key: value for key, value in START.items() if key != "type"}
    assert (rejected_json(no_type).code, rejected_json(no_type).where) == (
        codes.INVALID_MESSAGE,
        "type",
    )
    assert decode(json.dumps({**START, "v": 1.0}), "json") == Start("r1", "dp", "ada")


def test_unknown_type_and_wrong_direction() -> None:
    assert rejected_json({**START, "type": "hello"}).code == codes.UNKNOWN_TYPE
    frames_text = json.dumps(FRAMES)
    from_client = decode(frames_text, "json", sender="client")
    assert isinstance(from_client, ProtocolError)
    assert (from_client.code, from_client.id, from_client.fatal) == (codes.UNKNOWN_TYPE, "r1", True)
    assert isinstance(decode(frames_text, "json", sender="server"), Frames)
    start_from_server = decode(json.dumps(START), "json", sender="server")
    assert isinstance(start_from_server, ProtocolError)
    assert start_from_server.code == codes.UNKNOWN_TYPE


@pytest.mark.parametrize(
    ("payload", "where", "fragment"),
    [
        ({**START, "colour": "red"}, None, "unexpected field 'colour'"),
        (
            {key: value for key, value in START.items() if key != "engine"},
            None,
            "missing field 'engine'",
        ),
        ({**START, "fps": "60"}, "fps", "must be a number"),
        ({**START, "fps": True}, "fps", "must be a number"),
        ({**START, "fps": 0}, "fps", "must be >= 1"),
        ({**START, "fps": 0.5}, "fps", "must be >= 1, got 0.5"),
        ({**START, "fps": 1e-308}, "fps", "must be >= 1, got 1e-308"),
        ({**FRAMES, "fps": 0.999}, "fps", "must be >= 1"),
        ({**START, "fps": 1001}, "fps", "must be <= 1000"),
        ({**START, "engine": ""}, "engine", "1 to 128 characters"),
        ({**START, "engine": "a\nb"}, "engine", "control characters"),
        ({**START, "latency_budget_ms": -5}, "latency_budget_ms", "must be > 0"),
        ({**START, "channels": ["jawOpen", "jawOpen"]}, "channels", "distinct"),
        ({**START, "channels": []}, "channels", "1 to 1024"),
        ({**START, "channels": ["jawOpen"], "output": {"naming": "arkit"}}, None, "not both"),
        ({**START, "output": {"naming": "maya"}}, "output.naming", "must be one of"),
        ({**START, "output": {"naming": "arkit", "visemes": "oculus15"}}, "output", "omit it"),
        (
            {**START, "output": {"transforms": {"jawOpen": {"clamp": [1, 0]}}}},
            "output.transforms.jawOpen.clamp",
            "exceeds high",
        ),
        (
            {**START, "output": {"transforms": {"jawOpen": {"clamp": [0]}}}},
            "output.transforms.jawOpen.clamp",
            "[low, high]",
        ),
        (
            {**START, "output": {"transforms": {"jawOpen": {"gain": 2}}}},
            "output.transforms.jawOpen",
            "unexpected field 'gain'",
        ),
        ({**START, "options": {"a": 2**64}}, "options.a", "64 bits"),
        ({**START, "options": [1]}, "options", "must be an object"),
        (
            {**START, "options": {"deep": json.loads("[" * 20 + "]" * 20)}},
            "options.deep" + "[0]" * 15,
            "deeper than 16",
        ),
        (
            {"v": 1, "type": "audio", "id": "r1", "sample_rate": 7999, "pcm16": "AAA="},
            "sample_rate",
            "must be in [8000, 192000]",
        ),
        (
            {"v": 1, "type": "done", "id": "r1", "stats": {"frames": -1}},
            "stats.frames",
            "must be in",
        ),
        (
            {"v": 1, "type": "done", "id": "r1", "stats": {"frames": 1.5}},
            "stats.frames",
            "must be an integer",
        ),
        (
            {"v": 1, "type": "done", "id": "r1", "stats": {"frames": 1}, "reason": "bored"},
            "reason",
            "must be one of",
        ),
        ({**FRAMES, "n_channels": 0}, "n_channels", "must be in [1, 1024]"),
        ({**FRAMES, "data": [[0.0, True]]}, "data[0]", "must be numbers"),
        (
            {"v": 1, "type": "interrupt", "id": "r1", "at": 1.0, "return_ms": 20000},
            "return_ms",
            "must be <= 10000",
        ),
        # A resume.seq of 2^53 - 1 once passed, and the server then numbered a block 2^53.
        (
            {**START, "resume": {"frames": 0, "seq": 2**53 - 1}},
            "resume.seq",
            "must be in [0, 2147483647]",
        ),
        ({**START, "resume": {"frames": 0, "seq": 2**31}}, "resume.seq", "2147483647"),
        ({**FRAMES, "seq": 2**31}, "seq", "must be in [0, 2147483647]"),
    ],
)
def test_invalid_fields_name_the_field(
    payload: dict[str, Any], where: str | None, fragment: str
) -> None:
    error = rejected_json(payload)
    assert (error.code, error.where) == (codes.INVALID_MESSAGE, where)
    assert fragment in error.message
    assert (error.id, error.fatal) == ("r1", True)


@pytest.mark.parametrize(
    ("path", "value", "code", "where"),
    [
        ("items.0.start", -0.5, codes.INVALID_TIMES, "items[0].start"),
        ("items.1.end", 0.1, codes.INVALID_TIMES, "items[1].end"),
        ("items.1.end", 0.05, codes.INVALID_TIMES, "items[1].end"),
        ("items.1.start", 0.05, codes.NON_MONOTONIC_TIMES, "items[1].start"),
        ("items.0.end", 90_000.0, codes.INVALID_TIMES, "items[0].end"),
        ("items.0.phoneme", "", codes.INVALID_MESSAGE, "items[0].phoneme"),
        ("items.0.phoneme", 7, codes.INVALID_MESSAGE, "items[0].phoneme"),
        ("items", [], codes.INVALID_MESSAGE, "items"),
    ],
)
def test_bad_phoneme_items(path: str, value: Any, code: str, where: str) -> None:
    error = rejected_json(with_field(PHONEMES, path, value))
    assert (error.code, error.where, error.id, error.fatal) == (code, where, "r1", True)


def test_json_numbers_beyond_double_range_are_invalid_times() -> None:
    text = json.dumps(PHONEMES).replace('"start": 0.0', '"start": 1e400', 1)
    error = decode(text, "json")
    assert isinstance(error, ProtocolError)
    assert (error.code, error.where, error.message) == (
        codes.INVALID_TIMES,
        "items[0].start",
        "must be finite, got inf",
    )


@pytest.mark.parametrize(
    ("payload", "number", "code", "where"),
    [
        (with_field(PHONEMES, "items.0.end", "<n>"), "-1e999", codes.INVALID_TIMES, "items[0].end"),
        ({**START, "options": {"x": "<n>"}}, "1e400", codes.INVALID_MESSAGE, "options.x"),
        (
            {**START, "options": {"x": [{"y": "<n>"}]}},
            "-1e400",
            codes.INVALID_MESSAGE,
            "options.x[0].y",
        ),
        ({**START, "fps": "<n>"}, "1e999", codes.INVALID_MESSAGE, "fps"),
        (
            {**START, "output": {"transforms": {"jawOpen": {"offset": "<n>"}}}},
            "1e999",
            codes.INVALID_MESSAGE,
            "output.transforms.jawOpen.offset",
        ),
        (
            {"v": 1, "type": "interrupt", "id": "r1", "at": "<n>"},
            "1e999",
            codes.INVALID_TIMES,
            "at",
        ),
    ],
)
def test_json_overflow_anywhere_is_a_located_error(
    payload: dict[str, Any], number: str, code: str, where: str
) -> None:
    text = json.dumps(payload).replace('"<n>"', number)
    assert number in text
    error = decode(text, "json")
    assert isinstance(error, ProtocolError)
    assert (error.code, error.where, error.id, error.fatal) == (code, where, "r1", True)
    assert error.message.startswith("must be finite")


@pytest.mark.parametrize("value", [math.inf, -math.inf, math.nan])
@pytest.mark.parametrize("single_float", [False, True])
def test_msgpack_non_finite_floats_of_either_width_are_located_errors(
    value: float, single_float: bool
) -> None:
    for payload, code, where in (
        ({**START, "options": {"x": value}}, codes.INVALID_MESSAGE, "options.x"),
        ({**START, "latency_budget_ms": value}, codes.INVALID_MESSAGE, "latency_budget_ms"),
        (with_field(PHONEMES, "items.1.end", value), codes.INVALID_TIMES, "items[1].end"),
    ):
        error = rejected_msgpack(msgpack.packb(payload, use_single_float=single_float))
        assert (error.code, error.where, error.fatal) == (code, where, True)


def test_phonemes_touching_within_tolerance_are_accepted() -> None:
    result = decode(json.dumps(with_field(PHONEMES, "items.1.start", 0.1 - 1e-12)), "json")
    assert isinstance(result, Phonemes) and result.items[1].start == 0.1 - 1e-12


def test_nan_and_infinity_in_msgpack_are_rejected() -> None:
    nan_start = with_field(PHONEMES, "items.0.start", math.nan)
    error = rejected_msgpack(msgpack.packb(nan_start))
    assert (error.code, error.where) == (codes.INVALID_TIMES, "items[0].start")
    inf_fps = rejected_msgpack(msgpack.packb({**START, "fps": math.inf}))
    assert (inf_fps.code, inf_fps.where) == (codes.INVALID_MESSAGE, "fps")
    nan_option = rejected_msgpack(msgpack.packb({**START, "options": {"w": [math.nan]}}))
    assert (nan_option.code, nan_option.where) == (codes.INVALID_MESSAGE, "options.w[0]")


def test_interrupt_time_must_be_a_finite_non_negative_offset() -> None:
    interrupt = {"v": 1, "type": "interrupt", "id": "r1", "at": -1.0}
    assert rejected_json(interrupt).code == codes.INVALID_TIMES
    assert (
        rejected_msgpack(msgpack.packb({**interrupt, "at": math.nan})).code == codes.INVALID_TIMES
    )


@pytest.mark.parametrize(
    ("pcm16", "code"),
    [
        ("AAA=", codes.INVALID_AUDIO),  # 2 bytes: fine below, odd here is tested separately
        ("AA==", codes.INVALID_AUDIO),  # 1 byte: half a sample
        ("AAAA AAA=", codes.INVALID_AUDIO),  # whitespace is not base64
        ("AAA", codes.INVALID_AUDIO),  # missing padding
        (12, codes.INVALID_MESSAGE),
    ],
)
def test_bad_audio(pcm16: Any, code: str) -> None:
    payload = {"v": 1, "type": "audio", "id": "r1", "sample_rate": 16000, "pcm16": pcm16}
    result = decode(json.dumps(payload), "json")
    if pcm16 == "AAA=":
        assert not isinstance(result, ProtocolError)
        return
    assert isinstance(result, ProtocolError)
    assert (result.code, result.where) == (code, "pcm16")


def test_audio_in_msgpack_must_be_bin_of_whole_samples() -> None:
    audio = {"v": 1, "type": "audio", "id": "r1", "sample_rate": 16000}
    odd = rejected_msgpack(msgpack.packb({**audio, "pcm16": b"\x00\x01\x02"}, use_bin_type=True))
    assert odd.code == codes.INVALID_AUDIO
    text = rejected_msgpack(msgpack.packb({**audio, "pcm16": "AAA="}, use_bin_type=True))
    assert text.code == codes.INVALID_MESSAGE


def test_bad_frames_data() -> None:
    assert rejected_json({**FRAMES, "data": [[0.0, 1.0], [0.5]]}).code == codes.INVALID_FRAMES
    too_big = rejected_json({**FRAMES, "data": [[0.0, 1e39]]})
    assert (too_big.code, too_big.message) == (codes.INVALID_FRAMES, "values must fit in float32")
    assert rejected_json({**FRAMES, "data": [[0.0, 10**400]]}).code == codes.INVALID_FRAMES
    binary = {**FRAMES, "data": struct.pack("<3f", 0.0, 1.0, 2.0)}
    assert rejected_msgpack(msgpack.packb(binary, use_bin_type=True)).code == codes.INVALID_FRAMES
    nan_row = {**FRAMES, "data": struct.pack("<2f", 0.0, math.nan)}
    assert rejected_msgpack(msgpack.packb(nan_row, use_bin_type=True)).code == codes.INVALID_FRAMES
    inf_row = {**FRAMES, "data": struct.pack("<2f", -math.inf, 0.0)}
    assert rejected_msgpack(msgpack.packb(inf_row, use_bin_type=True)).code == codes.INVALID_FRAMES
    rows_in_msgpack = rejected_msgpack(msgpack.packb(FRAMES, use_bin_type=True))
    assert (rows_in_msgpack.code, rows_in_msgpack.where) == (codes.INVALID_MESSAGE, "data")


def test_request_id_is_reported_only_when_readable() -> None:
    assert rejected_json({**START, "fps": -1}).id == "r1"
    nameless = rejected_json({**START, "id": "", "fps": -1})
    assert (nameless.id, nameless.fatal) == (None, False)
    surrogate = decode('{"v":1,"type":"end","id":"\\ud800"}', "json")
    assert isinstance(surrogate, ProtocolError)
    assert (surrogate.code, surrogate.where, surrogate.id) == (codes.INVALID_MESSAGE, "id", None)


def test_error_messages_allow_a_null_id_but_not_a_missing_one() -> None:
    error = {"v": 1, "type": "error", "code": "server_busy", "message": "full", "fatal": True}
    assert decode(json.dumps({**error, "id": None}), "json") == ErrorMessage(
        "server_busy", "full", None, True
    )
    assert rejected_json(error).message == "missing field 'id'"
    assert rejected_json({**error, "id": None, "code": "Busy!"}).where == "code"


def test_size_limit_counts_bytes_and_closes_the_connection() -> None:
    text = json.dumps({**START, "engine": "é" * 40}, ensure_ascii=False)
    limit = len(text.encode())
    assert isinstance(decode(text, "json", max_size=limit), Start)
    error = decode(text, "json", max_size=limit - 1)
    assert isinstance(error, ProtocolError)
    assert (error.code, error.id, error.fatal) == (codes.MESSAGE_TOO_LARGE, None, True)
    assert len(text) < limit - 1  # characters alone would have passed
    data = msgpack.packb(START)
    assert isinstance(decode(data, "msgpack", max_size=len(data)), Start)
    assert decode(data, "msgpack", max_size=len(data) - 1) == ProtocolError(
        codes.MESSAGE_TOO_LARGE,
        f"message of {len(data)} bytes exceeds the limit of {len(data) - 1} bytes",
        None,
        True,
    )


def test_protocol_error_becomes_an_error_message() -> None:
    error = rejected_json({**START, "fps": -1})
    assert error.to_message() == ErrorMessage(
        codes.INVALID_MESSAGE, "fps: must be >= 1, got -1.0", "r1", True
    )
    assert str(error) == "fps: must be >= 1, got -1.0 [invalid_message]"


def test_error_for_a_huge_field_name_still_encodes() -> None:
    error = rejected_json({**START, "x" * 100_000: 1})
    message = error.to_message()
    assert len(message.message) == 4096 and message.message.endswith("...")
    assert message.message.startswith("unexpected field 'xxx")
    assert decode(encode(message, "json"), "json") == message


def test_encode_refuses_invalid_messages() -> None:
    with pytest.raises(EncodeError) as caught:
        encode(Phonemes("r1", (PhonemeItem("AA", 0.5, 0.2),)), "json")
    assert (caught.value.error.code, caught.value.error.where) == (
        codes.INVALID_TIMES,
        "items[0].end",
    )
    with pytest.raises(EncodeError):
        encode(Start("r1", "dp", "ada", fps=math.nan), "msgpack")
    with pytest.raises(EncodeError):
        encode(Start("r1", "dp", "ada", options={"t": (1, 2)}), "msgpack")  # type: ignore[dict-item, call-overload]  # a tuple on purpose
    with pytest.raises(EncodeError):
        encode(Frames("r1", 0, 0, 60.0, 2, b"\x00" * 12), "msgpack")
    with pytest.raises(TypeError):
        encode({"type": "end"}, "json")  # type: ignore[call-overload]  # not a message, on purpose
    unchecked = encode(Start("r1", "dp", "ada", fps=-1.0), "msgpack", validate=False)
    assert msgpack.unpackb(unchecked)["fps"] == -1.0


def test_integral_floats_count_as_integers() -> None:
    payload = {"v": 1, "type": "done", "id": "r1", "stats": {"frames": 12.0}}
    done = decode(json.dumps(payload), "json")
    assert isinstance(done, Done), done
    assert done.stats.frames == 12 and isinstance(done.stats.frames, int)
