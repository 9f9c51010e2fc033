"""The JSON Schemas and the codec's hand-written checks agree (jsonschema is test-only)."""

from __future__ import annotations

import json
import re
from functools import cache
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from jsonschema import Draft202012Validator

from lipstream_client import ProtocolError, decode, encode, load_schema
from lipstream_client import errors as codes
from lipstream_client import messages as m
from lipstream_client.messages import MESSAGE_TYPES, Message
from lipstream_client.schema import schema_text
from lipstream_client.wire import message_to_wire
from tests.lipstream_client.strategies import messages

FIELD_NAMES = (
    "id",
    "fps",
    "channels",
    "output",
    "options",
    "items",
    "phoneme",
    "start",
    "end",
    "emotion",
    "pcm16",
    "sample_rate",
    "at",
    "return_ms",
    "data",
    "n_channels",
    "seq",
    "stats",
    "frames",
    "reason",
    "code",
    "message",
    "fatal",
    "details",
    "clamp",
    "naming",
    "visemes",
    "retarget",
    "transforms",
    "multiplier",
    "lookahead_ms",
    "resume",
    "fidelity",
    "audio",
    "v",
    "type",
)
# Rules JSON Schema cannot state, as (code, pattern on "where: message"); docs/reference/protocol.md
# lists the same rules.
BEYOND_SCHEMA = (
    (codes.INVALID_TIMES, r"\.end: end .* must be after start"),
    (codes.NON_MONOTONIC_TIMES, r"\.start: starts at .* before the previous phoneme ends"),
    (codes.INVALID_MESSAGE, r"\.clamp: low .* exceeds high"),
    (codes.INVALID_FRAMES, r"^data"),
    (codes.INVALID_AUDIO, r"^pcm16: must hold whole 16-bit samples"),
    (codes.INVALID_MESSAGE, r"nests deeper than|integers must fit in 64 bits"),
    (codes.INVALID_MESSAGE, r"must be finite|lone surrogates"),
    (codes.INVALID_TIMES, r"must be finite"),
)


@cache
def validator(message_type: str) -> Draft202012Validator:
    schema = load_schema(message_type)
    Draft202012Validator.check_schema(schema)
    return Draft202012Validator(schema)


def schema_accepts(payload: Any) -> bool:
    message_type = payload.get("type") if isinstance(payload, dict) else None
    if not isinstance(message_type, str) or message_type not in MESSAGE_TYPES:
        return False
    valid: bool = validator(message_type).is_valid(payload)
    return valid


@pytest.mark.parametrize(
    "payload",
    [
        {"v": 1, "type": "text", "id": "0", "text": "hi", "rate": None, "voice": None},
        {"v": 1, "type": "audio", "id": "0", "sample_rate": 16000, "pcm16": "AAA=", "start": None},
    ],
)
def test_a_null_optional_field_is_absent_to_the_codec_and_the_schema(
    payload: dict[str, Any],
) -> None:
    """Found by the mutation test below: the codec read a null optional field of `text` as
    absent while the schema refused it."""
    assert schema_accepts(payload)
    decode(json.dumps(payload), "json")


@pytest.mark.parametrize("message_type", sorted(MESSAGE_TYPES))
def test_each_schema_is_valid_draft_2020_12(message_type: str) -> None:
    schema = load_schema(message_type)
    assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    assert schema["properties"]["type"] == {"const": message_type}
    assert schema["properties"]["v"]["const"] == 1
    assert schema["additionalProperties"] is False
    validator(message_type)
    assert json.loads(schema_text(message_type)) == schema


def test_unknown_schema_is_a_key_error() -> None:
    with pytest.raises(KeyError, match="no message type"):
        load_schema("hello")


@settings(max_examples=200, deadline=None)
@given(messages())
def test_every_encoded_message_satisfies_its_schema(message: Message) -> None:
    payload = json.loads(encode(message, "json"))
    errors = [error.message for error in validator(message.type).iter_errors(payload)]
    assert errors == []


def paths(node: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
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


# Each protocol limit, and a value just beyond it.
BOUNDARIES = sorted(
    {
        value
        for limit in (
            0,
            1,
            m.MIN_FPS,
            m.MAX_FPS,
            m.MAX_LATENCY_BUDGET_MS,
            m.MAX_RETURN_MS,
            m.MAX_TIME_S,
            m.MIN_SAMPLE_RATE,
            m.MAX_SAMPLE_RATE,
            m.MAX_INTEGER,
            m.MAX_SEQ,
            m.MAX_CHANNELS,
            m.MAX_TIME_S * 1000.0,
            2**63,
            2**64,
        )
        for value in (limit, -limit, limit + 1, limit + 0.5, limit - 1e-9)
    }
)

replacements = st.recursive(
    st.one_of(
        st.none(),
        st.booleans(),
        st.integers(-(2**70), 2**70),
        st.sampled_from(BOUNDARIES),
        st.floats(allow_nan=False, allow_infinity=False, width=64),
        st.sampled_from(["", "x", "a\n", "oculus15", "livelink", "end", "AAA=", "AA=="]),
        st.text(max_size=6),
    ),
    lambda inner: (
        st.lists(inner, max_size=3)
        | st.dictionaries(st.sampled_from(FIELD_NAMES) | st.text(max_size=4), inner, max_size=3)
    ),
    max_leaves=6,
)


@st.composite
def mutated(draw: st.DrawFn) -> dict[str, Any]:
    payload: dict[str, Any] = json.loads(json.dumps(message_to_wire(draw(messages()), "json")))
    for _ in range(draw(st.integers(1, 2))):
        path = draw(st.sampled_from(paths(payload)))
        node: Any = payload
        for key in path[:-1]:
            node = node[key]
        action = draw(st.sampled_from(("replace", "remove", "add")))
        if action == "remove" and isinstance(node, dict):
            del node[path[-1]]
        elif action == "add" and isinstance(node, dict):
            node[draw(st.sampled_from(FIELD_NAMES))] = draw(replacements)
        else:
            node[path[-1]] = draw(replacements)
        if not paths(payload):
            break
    return payload


def beyond_schema(error: ProtocolError) -> bool:
    text = f"{error.where}: {error.message}" if error.where else error.message
    return any(error.code == code and re.search(pattern, text) for code, pattern in BEYOND_SCHEMA)


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(mutated())
def test_codec_and_schema_agree_on_mutated_messages(payload: dict[str, Any]) -> None:
    result = decode(json.dumps(payload), "json")
    if isinstance(result, ProtocolError):
        assert not schema_accepts(payload) or beyond_schema(result), (result, payload)
    else:
        assert schema_accepts(payload), (result, payload)


@pytest.mark.parametrize(
    ("payload", "beyond"),
    [
        (
            {
                "v": 1,
                "type": "phonemes",
                "id": "a",
                "items": [{"phoneme": "AA", "start": 0.5, "end": 0.5}],
            },
            True,
        ),
        (
            {
                "v": 1,
                "type": "phonemes",
                "id": "a",
                "items": [
                    {"phoneme": "AA", "start": 0.0, "end": 0.5},
                    {"phoneme": "B", "start": 0.25, "end": 0.75},
                ],
            },
            True,
        ),
        (
            {
                "v": 1,
                "type": "frames",
                "id": "a",
                "seq": 0,
                "first_frame": 0,
                "fps": 60,
                "n_channels": 3,
                "data": [[0.0, 1.0]],
            },
            True,
        ),
        ({"v": 1, "type": "audio", "id": "a", "sample_rate": 16000, "pcm16": "AA=="}, True),
        (
            {
                "v": 1,
                "type": "start",
                "id": "a",
                "engine": "e",
                "character": "c",
                "output": {"transforms": {"x": {"clamp": [2, 1]}}},
            },
            True,
        ),
        ({"v": 1, "type": "start", "id": "a", "engine": "e", "character": "c", "fps": -1}, False),
        ({"v": 1, "type": "start", "id": "a", "engine": "e", "character": "c", "colour": 1}, False),
    ],
)
def test_beyond_schema_rules_are_exactly_the_listed_ones(
    payload: dict[str, Any], beyond: bool
) -> None:
    result = decode(json.dumps(payload), "json")
    assert isinstance(result, ProtocolError)
    assert schema_accepts(payload) == beyond
    assert beyond_schema(result) == beyond
