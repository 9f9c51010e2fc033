"""The plain ``phonemes`` path of the decoder builds what the field readers build.

``validate.plain_phonemes`` takes a ``phonemes`` payload in its plainest shape without
the readers and answers None for anything else, which the readers then accept or
reject. Each case here is checked against the readers (``validate._phonemes`` after the
envelope check), and against the message or error code written out by hand: a plain
payload gives the same message, and a payload off the plain shape by one detail gives
None from the plain path and the readers' own answer from ``decode``.
"""

from __future__ import annotations

import copy
from typing import Any

import msgpack
import pytest
from hypothesis import given, settings

from lipstream_client import PhonemeItem, Phonemes, ProtocolError, decode
from lipstream_client._fields import InvalidField
from lipstream_client.validate import _check_version, _phonemes, plain_phonemes
from tests.lipstream_client.strategies import phonemes_messages


def payload(*items: dict[str, Any], identifier: Any = "r1", **extra: Any) -> dict[str, Any]:
    return {"v": 1, "type": "phonemes", "id": identifier, "items": list(items), **extra}


def item(phoneme: Any = "AA", start: Any = 0.0, end: Any = 0.1, **extra: Any) -> dict[str, Any]:
    return {"phoneme": phoneme, "start": start, "end": end, **extra}


def by_readers(wire: dict[str, Any]) -> Phonemes | str:
    """What the field readers make of ``wire``: the message, or the code of their error."""
    try:
        _check_version(wire)
        return _phonemes(wire, "msgpack")
    except InvalidField as error:
        return error.code


def decoded(wire: dict[str, Any]) -> Phonemes | str:
    message = decode(msgpack.packb(wire, use_bin_type=True), "msgpack", sender="client")
    if isinstance(message, ProtocolError):
        return message.code
    assert isinstance(message, Phonemes)
    return message


PLAIN = [
    (payload(item()), Phonemes("r1", (PhonemeItem("AA", 0.0, 0.1),))),
    (
        payload(item("m", 0.0, 0.08), item("AA", 0.08, 0.2, emotion="happy")),
        Phonemes("r1", (PhonemeItem("m", 0.0, 0.08), PhonemeItem("AA", 0.08, 0.2, "happy"))),
    ),
    (  # touching within the tolerance of the previous end
        payload(item("B", 1.0, 1.5), item("IY", 1.5 - 1e-10, 2.0)),
        Phonemes("r1", (PhonemeItem("B", 1.0, 1.5), PhonemeItem("IY", 1.5 - 1e-10, 2.0))),
    ),
    (
        payload(item("sil", 86_399.0, 86_400.0), identifier="x" * 128),
        Phonemes("x" * 128, (PhonemeItem("sil", 86_399.0, 86_400.0),)),
    ),
]


@pytest.mark.parametrize(("wire", "expected"), PLAIN)
def test_a_plain_payload_is_the_message_the_readers_build(
    wire: dict[str, Any], expected: Phonemes
) -> None:
    assert plain_phonemes(copy.deepcopy(wire)) == expected
    assert by_readers(copy.deepcopy(wire)) == expected
    assert decoded(wire) == expected


OFF_THE_PLAIN_SHAPE = [
    (payload(item(start=0, end=1)), None),  # integer times: the readers take them
    (payload(item(emotion=None)), None),  # a null emotion: absent to the readers
    (payload(item(), identifier="r\u00e9"), None),  # non-ASCII id
    (payload(item("\u0251")), None),  # an IPA label
    ({**payload(item()), "v": 1.0}, None),  # the version as a float
    (payload(item(), extra=1), "invalid_message"),
    (payload(item(extra=1)), "invalid_message"),
    (payload(item(), identifier="r\n1"), "invalid_message"),
    (payload(item(), identifier=""), "invalid_message"),
    (payload(item(), identifier="x" * 129), "invalid_message"),
    (payload(item("A\tA")), "invalid_message"),
    (payload(item("")), "invalid_message"),
    (payload(item("A" * 33)), "invalid_message"),
    (payload(item(emotion="")), "invalid_message"),
    (payload(item(start=True)), "invalid_message"),
    (payload(item(start=0.2, end=0.1)), "invalid_times"),
    (payload(item(start=0.1, end=0.1)), "invalid_times"),
    (payload(item(start=-0.1)), "invalid_times"),
    (payload(item(start=86_400.0, end=86_400.5)), "invalid_times"),
    (payload(item(end=float("inf"))), "invalid_times"),
    (payload(item(end=float("nan"))), "invalid_times"),
    (payload(item("AA", 0.0, 0.2), item("B", 0.1, 0.3)), "non_monotonic_times"),
    (payload(), "invalid_message"),
    ({**payload(item()), "v": True}, "invalid_message"),
    ({**payload(item()), "v": 2}, "unsupported_version"),
    ({**payload(item()), "items": "AA"}, "invalid_message"),
    ({**payload(item()), "items": [["AA", 0.0, 0.1]]}, "invalid_message"),
]


@pytest.mark.parametrize(("wire", "readers"), OFF_THE_PLAIN_SHAPE)
def test_a_payload_off_the_plain_shape_goes_to_the_readers(
    wire: dict[str, Any], readers: str | None
) -> None:
    assert plain_phonemes(copy.deepcopy(wire)) is None
    expected = by_readers(copy.deepcopy(wire))
    if readers is None:
        assert isinstance(expected, Phonemes)
    else:
        assert expected == readers
    assert decoded(wire) == expected


def test_a_server_may_not_send_phonemes_even_plain_ones() -> None:
    wire = msgpack.packb(payload(item()), use_bin_type=True)
    error = decode(wire, "msgpack", sender="server")
    assert isinstance(error, ProtocolError) and error.code == "unknown_type"


@settings(max_examples=200, deadline=None)
@given(phonemes_messages)
def test_any_valid_message_decodes_to_itself_whichever_path(message: Phonemes) -> None:
    wire = payload(
        *(
            {"phoneme": i.phoneme, "start": i.start, "end": i.end}
            | ({} if i.emotion is None else {"emotion": i.emotion})
            for i in message.items
        ),
        identifier=message.id,
    )
    plain = plain_phonemes(copy.deepcopy(wire))
    assert plain is None or plain == message
    assert by_readers(copy.deepcopy(wire)) == message
    assert decoded(wire) == message
