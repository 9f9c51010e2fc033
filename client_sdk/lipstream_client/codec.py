"""Encode and decode lipstream messages, sans I/O: bytes or text in, typed messages out.

Sketch: the WebSocket subprotocol fixes the encoding for a connection:
``lipstream.v1.msgpack`` sends binary frames, ``lipstream.v1.json`` text
frames. ``decode`` takes one frame's payload and returns a typed message or
a ``ProtocolError`` value; it never raises on bad input. It checks the size
before parsing, parses msgpack without ext types (so no extension hook, and
no msgpack-numpy, can run code), rejects duplicate and non-string keys and
non-standard JSON constants, and then validates the structure field by field
(``validate``). ``encode`` runs the same validation on what it is about to
send, so a peer never receives what this codec would reject.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from typing import Any, Literal, overload

import msgpack

from ._fields import InvalidField
from .errors import MALFORMED, MESSAGE_TOO_LARGE, EncodeError, ProtocolError
from .messages import ENCODINGS, MESSAGE_TYPES, Encoding, Message, Sender
from .validate import message_from_wire, message_id
from .wire import message_to_wire

SUBPROTOCOL_MSGPACK = "lipstream.v1.msgpack"
SUBPROTOCOL_JSON = "lipstream.v1.json"
SUBPROTOCOLS: dict[str, Encoding] = {SUBPROTOCOL_MSGPACK: "msgpack", SUBPROTOCOL_JSON: "json"}
DEFAULT_ENCODING: Encoding = "msgpack"
DEFAULT_MAX_SIZE = 1 << 20
_UTF8_MAX_BYTES_PER_CHAR = 4
_MESSAGE_CLASSES = tuple(MESSAGE_TYPES.values())


def subprotocol_for(encoding: Encoding) -> str:
    """The subprotocol name that selects ``encoding``."""
    _check_encoding(encoding)
    return SUBPROTOCOL_MSGPACK if encoding == "msgpack" else SUBPROTOCOL_JSON


def encoding_for_subprotocol(subprotocol: str | None) -> Encoding | None:
    """The encoding of a negotiated subprotocol: None negotiated means the default
    (msgpack); an unknown name gives None."""
    if subprotocol is None:
        return DEFAULT_ENCODING
    return SUBPROTOCOLS.get(subprotocol)


def select_subprotocol(offered: Iterable[str]) -> str | None:
    """Server side: the first subprotocol in the client's offer that this codec speaks."""
    return next((name for name in offered if name in SUBPROTOCOLS), None)


@overload
def encode(message: Message, encoding: Literal["msgpack"], *, validate: bool = True) -> bytes: ...
@overload
def encode(message: Message, encoding: Literal["json"], *, validate: bool = True) -> str: ...
@overload
def encode(message: Message, encoding: Encoding, *, validate: bool = True) -> bytes | str: ...


def encode(message: Message, encoding: Encoding, *, validate: bool = True) -> bytes | str:
    """One WebSocket frame's payload: ``bytes`` for msgpack, ``str`` for JSON.

    With ``validate`` (the default), EncodeError if the message breaks a
    protocol rule; without it, a hot path skips the check and trusts its input.
    """
    _check_encoding(encoding)
    if not isinstance(message, _MESSAGE_CLASSES):
        raise TypeError(f"not a lipstream message: {type(message).__name__}")
    payload = message_to_wire(message, encoding)
    if validate:
        try:
            message_from_wire(payload, encoding, None)
        except InvalidField as error:
            raise EncodeError(_protocol_error(error, message_id(payload))) from None
    if encoding == "msgpack":
        packed: bytes = msgpack.packb(payload, use_bin_type=True)
        return packed
    return json.dumps(payload, ensure_ascii=False, allow_nan=False, separators=(",", ":"))


def decode(
    data: bytes | bytearray | memoryview | str,
    encoding: Encoding,
    *,
    max_size: int = DEFAULT_MAX_SIZE,
    sender: Sender | None = None,
) -> Message | ProtocolError:
    """The message in one frame's payload, or the ``ProtocolError`` that rejects it.

    ``max_size`` bounds the payload in bytes (UTF-8 bytes for text).
    ``sender`` accepts only that side's message types: a server decodes with
    ``sender="client"``. Errors naming a readable request id are fatal for
    that request; others leave the connection serving, except
    ``message_too_large``, which closes it (1009).
    """
    _check_encoding(encoding)
    size = _size(data, max_size)
    if size > max_size:
        return ProtocolError(
            MESSAGE_TOO_LARGE,
            f"message of {size} bytes exceeds the limit of {max_size} bytes",
            fatal=True,
        )
    payload = parse_payload(data, encoding)
    if isinstance(payload, ProtocolError):
        return payload
    return payload_message(payload, encoding, sender)


def payload_message(
    payload: object, encoding: Encoding, sender: Sender | None = None
) -> Message | ProtocolError:
    """The message in an already parsed payload (as ``parse_payload`` returns it), or the
    ``ProtocolError`` that rejects it: ``decode`` without the size check and the parse."""
    _check_encoding(encoding)
    try:
        return message_from_wire(payload, encoding, sender)
    except InvalidField as error:
        return _protocol_error(error, message_id(payload))


def _protocol_error(error: InvalidField, identifier: str | None) -> ProtocolError:
    return ProtocolError(error.code, error.message, identifier, identifier is not None, error.where)


def _check_encoding(encoding: str) -> None:
    if encoding not in ENCODINGS:
        raise ValueError(f"encoding must be one of {ENCODINGS}, got {encoding!r}")


def _size(data: bytes | bytearray | memoryview | str, max_size: int) -> int:
    """Payload size in bytes; text is measured exactly only when it might exceed the limit."""
    if not isinstance(data, str):
        return memoryview(data).nbytes
    if len(data) > max_size or len(data) * _UTF8_MAX_BYTES_PER_CHAR <= max_size:
        return len(data)
    return len(data.encode("utf-8", "surrogatepass"))


def parse_payload(data: bytes | bytearray | memoryview | str, encoding: Encoding) -> object:
    """The parsed payload (maps, lists, scalars), or a ``malformed`` ProtocolError.

    Parser failures arrive as ValueError (including UnicodeDecodeError and
    msgpack's ExtraData, FormatError, StackError), msgpack's
    UnpackException, TypeError from ``_unique_keys``, or RecursionError
    from deeply nested JSON.
    """
    try:
        if encoding == "msgpack":
            if isinstance(data, str):
                return _malformed("msgpack messages travel in binary frames, got text")
            return msgpack.unpackb(
                data,
                raw=False,
                strict_map_key=True,
                max_ext_len=0,
                use_list=True,
                object_pairs_hook=_unique_keys,
            )
        text = data if isinstance(data, str) else bytes(data).decode("utf-8")
        return json.loads(text, object_pairs_hook=_unique_keys, parse_constant=_reject_constant)
    except (ValueError, TypeError, RecursionError, msgpack.UnpackException) as error:
        return _malformed(f"not valid {encoding}: {_short(error)}")


def _unique_keys(pairs: list[tuple[Any, Any]]) -> dict[str, Any]:
    result: dict[str, Any] = {}
    for key, value in pairs:
        if not isinstance(key, str):
            raise TypeError(f"map keys must be strings, got {type(key).__name__}")
        if key in result:
            raise ValueError(f"duplicate key {key[:64]!r}")
        result[key] = value
    return result


def _reject_constant(name: str) -> float:
    raise ValueError(f"{name} is not a JSON number")


def _malformed(message: str) -> ProtocolError:
    return ProtocolError(MALFORMED, message)


def _short(error: BaseException) -> str:
    text = str(error) or type(error).__name__
    return text if len(text) <= 200 else text[:200] + "..."
