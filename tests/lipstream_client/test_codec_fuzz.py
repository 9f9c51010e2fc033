"""Fuzzing: decode returns a message or a documented ProtocolError for every input, never raises."""

from __future__ import annotations

import json
from typing import Any

import msgpack
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from lipstream_client import ERROR_CODES, Encoding, ProtocolError, decode, encode
from lipstream_client.messages import MESSAGE_TYPES, Message
from lipstream_client.wire import message_to_wire
from tests.lipstream_client.strategies import messages

MESSAGE_CLASSES = tuple(MESSAGE_TYPES.values())
CODEC_CODES = {code for code, info in ERROR_CODES.items() if info.origin == "codec"}
FIELD_NAMES = sorted(
    {
        "id",
        "engine",
        "character",
        "fps",
        "channels",
        "output",
        "emotion",
        "latency_budget_ms",
        "options",
        "items",
        "sample_rate",
        "pcm16",
        "at",
        "return_ms",
        "lookahead_ms",
        "fidelity",
        "seq",
        "first_frame",
        "n_channels",
        "data",
        "stats",
        "reason",
        "code",
        "message",
        "fatal",
        "details",
        "phoneme",
        "start",
        "end",
        "naming",
        "transforms",
        "visemes",
        "clamp",
    }
)
FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])

scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(),
    st.floats(),
    st.text(max_size=8),
)
json_like = st.recursive(
    scalars,
    lambda inner: (
        st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner, max_size=4)
    ),
    max_leaves=12,
)
msgpack_like = st.recursive(
    st.one_of(
        st.none(),
        st.booleans(),
        st.integers(-(2**63), 2**64 - 1),
        st.floats(),
        st.text(max_size=8),
        st.binary(max_size=8),
    ),
    lambda inner: (
        st.lists(inner, max_size=4)
        | st.dictionaries(
            st.one_of(st.text(max_size=6), st.integers(0, 9), st.binary(max_size=4)),
            inner,
            max_size=4,
        )
    ),
    max_leaves=12,
)
envelopes = st.fixed_dictionaries(
    {
        "v": st.sampled_from([1, 1, 1, 2, "1", None]),
        "type": st.sampled_from([*MESSAGE_TYPES, "hello", 5]),
    },
    optional={name: json_like for name in FIELD_NAMES},
)


def packed(value: Any) -> bytes | None:
    """msgpack bytes of ``value``, or None when msgpack cannot hold its integers."""
    try:
        packed_value: bytes = msgpack.packb(value, use_bin_type=True)
        return packed_value
    except OverflowError:
        return None


def assert_outcome(result: object) -> None:
    if isinstance(result, ProtocolError):
        assert result.code in CODEC_CODES, result
        assert result.fatal == (result.id is not None) or result.code == "message_too_large"
        assert result.message
        report = result.to_message()
        for encoding in ("msgpack", "json"):
            assert decode(encode(report, encoding), encoding) == report
        return
    assert isinstance(result, MESSAGE_CLASSES), result


def decode_everywhere(data: bytes | str) -> None:
    for encoding in ("msgpack", "json"):
        for sender in (None, "client", "server"):
            assert_outcome(decode(data, encoding, sender=sender))


@FUZZ
@given(st.binary(max_size=256))
def test_arbitrary_bytes(data: bytes) -> None:
    decode_everywhere(data)


@FUZZ
@given(st.text(max_size=256))
def test_arbitrary_text(text: str) -> None:
    decode_everywhere(text)


@FUZZ
@given(json_like)
def test_arbitrary_json_values(value: Any) -> None:
    decode_everywhere(json.dumps(value))


@FUZZ
@given(msgpack_like)
def test_arbitrary_msgpack_values(value: Any) -> None:
    decode_everywhere(msgpack.packb(value, use_bin_type=True))


@FUZZ
@given(envelopes)
def test_envelopes_with_arbitrary_fields(payload: dict[str, Any]) -> None:
    decode_everywhere(json.dumps(payload))
    data = packed(payload)
    if data is not None:
        decode_everywhere(data)


def paths(node: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """Every key/index path inside a payload."""
    found: list[tuple[Any, ...]] = []
    children = (
        node.items()
        if isinstance(node, dict)
        else enumerate(node)
        if isinstance(node, list)
        else ()
    )
    for key, value in children:
        found.append((*prefix, key))
        found.extend(paths(value, (*prefix, key)))
    return found


@st.composite
def mutated_payloads(draw: st.DrawFn, encoding: Encoding) -> dict[str, Any]:
    """A valid message's wire payload with one field replaced, removed or added."""
    payload = message_to_wire(draw(messages()), encoding)
    path = draw(st.sampled_from(paths(payload)))
    *parents, last = path
    node: Any = payload
    for key in parents:
        node = node[key]
    action = draw(st.sampled_from(("replace", "remove", "add")))
    if action == "remove" and isinstance(node, dict):
        del node[last]
    elif action == "add" and isinstance(node, dict):
        node[draw(st.sampled_from(FIELD_NAMES))] = draw(json_like)
    else:
        node[last] = draw(json_like)
    return payload


@FUZZ
@given(st.data())
def test_mutated_valid_messages(data: st.DataObject) -> None:
    json_payload = data.draw(mutated_payloads("json"))
    decode_everywhere(json.dumps(json_payload))
    msgpack_data = packed(data.draw(mutated_payloads("msgpack")))
    if msgpack_data is not None:
        decode_everywhere(msgpack_data)


@settings(max_examples=150, deadline=None)
@given(messages(), st.integers(min_value=0))
def test_truncated_messages(message: Message, cut: int) -> None:
    for encoding in ("msgpack", "json"):
        wire = encode(message, encoding)
        decode_everywhere(wire[: cut % max(1, len(wire))])


def test_fuzz_inputs_reach_every_outcome() -> None:
    """The generators are not degenerate: hand-picked members hit acceptance and rejection."""
    accepted = decode('{"v":1,"type":"cancel","id":"x"}', "json")
    rejected = decode('{"v":1,"type":"cancel","id":"x","fps":1}', "json")
    assert isinstance(accepted, MESSAGE_CLASSES)
    assert isinstance(rejected, ProtocolError) and rejected.code == "invalid_message"
