"""Field readers for decoded msgpack/JSON values, one rule each, matching the JSON Schemas.

Sketch: each reader takes a plain value from the parser and a ``where`` path
(``items[2].end``) and returns the typed value or raises ``InvalidField``
with a protocol error code. ``validate`` composes them per message and
``codec`` turns the exception into a ``ProtocolError`` value, so nothing
leaves the decoder as an exception. Free-form maps are walked with an
explicit stack, so hostile nesting cannot exhaust the interpreter's recursion.
"""

from __future__ import annotations

import base64
import binascii
import math
import re
from collections.abc import Collection, Mapping
from typing import Any

from .errors import INVALID_MESSAGE
from .messages import (
    MAX_INTEGER,
    MAX_JSON_DEPTH,
    MAX_MAP_ENTRIES,
    MAX_NAME_LENGTH,
    JsonValue,
)

# Schemas state these as "pattern" plus "not": {"pattern": <forbidden>} rather than
# relying on "$", which Python's re also matches before a final newline.
CONTROL_CHARACTERS = "[\\u0000-\\u001f\\u007f]"
ERROR_CODE_PATTERN = "^[a-z]"
ERROR_CODE_FORBIDDEN = "[^a-z0-9_]"
BASE64_PATTERN = "^(?:[A-Za-z0-9+/]{4})*(?:[A-Za-z0-9+/]{2}==|[A-Za-z0-9+/]{3}=)?$"
BASE64_FORBIDDEN = "[^A-Za-z0-9+/=]"
ERROR_CODE = re.compile("[a-z][a-z0-9_]*")
_INT64_MIN = -(2**63)
_UINT64_MAX = 2**64 - 1
_CONTROL = re.compile(CONTROL_CHARACTERS)
_BASE64 = re.compile(BASE64_PATTERN.removeprefix("^").removesuffix("$"))


class InvalidField(Exception):
    """Internal: a field broke a rule. Never escapes ``codec.decode``."""

    def __init__(self, code: str, where: str | None, message: str) -> None:
        super().__init__(message)
        self.code = code
        self.where = where
        self.message = message


def child(where: str, key: str) -> str:
    return f"{where}.{key}" if where else key


def read_object(
    value: object, where: str, required: Collection[str], optional: Collection[str] = ()
) -> dict[str, Any]:
    """A map with exactly the ``required`` keys plus any of ``optional``."""
    if not isinstance(value, dict):
        raise InvalidField(INVALID_MESSAGE, where or None, f"must be an object, got {_kind(value)}")
    for key in value:
        if not isinstance(key, str):
            raise InvalidField(INVALID_MESSAGE, where or None, "object keys must be strings")
    for key in required:
        if key not in value:
            raise InvalidField(INVALID_MESSAGE, where or None, f"missing field {key!r}")
    for key in value:
        if key not in required and key not in optional:
            raise InvalidField(INVALID_MESSAGE, where or None, f"unexpected field {key!r}")
    return value


def present(obj: Mapping[str, Any], key: str) -> bool:
    """Optional fields: absent and null mean the same."""
    return obj.get(key) is not None


def read_text(
    value: object,
    where: str,
    max_length: int,
    *,
    control: bool = False,
    pattern: re.Pattern[str] | None = None,
) -> str:
    """A non-empty string of at most ``max_length`` code points and valid UTF-8, without
    control characters unless ``control``, and wholly matching ``pattern`` if given."""
    if not isinstance(value, str):
        raise InvalidField(INVALID_MESSAGE, where, f"must be a string, got {_kind(value)}")
    if not 1 <= len(value) <= max_length:
        raise InvalidField(
            INVALID_MESSAGE, where, f"must be 1 to {max_length} characters, got {len(value)}"
        )
    require_utf8(value, where)
    if not control and _CONTROL.search(value):
        raise InvalidField(INVALID_MESSAGE, where, "must not contain control characters")
    if pattern is not None and not pattern.fullmatch(value):
        raise InvalidField(INVALID_MESSAGE, where, f"must match {pattern.pattern}")
    return value


def read_number(
    value: object,
    where: str,
    *,
    minimum: float | None = None,
    maximum: float | None = None,
    above: float | None = None,
    code: str = INVALID_MESSAGE,
) -> float:
    """A finite number (not a boolean) within [minimum, maximum] and > ``above``."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InvalidField(INVALID_MESSAGE, where, f"must be a number, got {_kind(value)}")
    number = _as_float(value)
    if not math.isfinite(number):
        raise InvalidField(code, where, f"must be finite, got {value!r}")
    if minimum is not None and number < minimum:
        raise InvalidField(code, where, f"must be >= {minimum:g}, got {number!r}")
    if above is not None and number <= above:
        raise InvalidField(code, where, f"must be > {above:g}, got {number!r}")
    if maximum is not None and number > maximum:
        raise InvalidField(code, where, f"must be <= {maximum:g}, got {number!r}")
    return number


def read_integer(value: object, where: str, *, minimum: int = 0, maximum: int = MAX_INTEGER) -> int:
    """An integer in [minimum, maximum]; integral floats such as 3.0 count as integers."""
    if isinstance(value, float) and math.isfinite(value) and value.is_integer():
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int):
        raise InvalidField(INVALID_MESSAGE, where, f"must be an integer, got {_kind(value)}")
    if not minimum <= value <= maximum:
        raise InvalidField(
            INVALID_MESSAGE, where, f"must be in [{minimum}, {maximum}], got {value}"
        )
    return value


def read_bool(value: object, where: str) -> bool:
    if not isinstance(value, bool):
        raise InvalidField(INVALID_MESSAGE, where, f"must be a boolean, got {_kind(value)}")
    return value


def read_choice(value: object, where: str, choices: Collection[str]) -> str:
    if not isinstance(value, str) or value not in choices:
        raise InvalidField(
            INVALID_MESSAGE, where, f"must be one of {sorted(choices)}, got {value!r}"
        )
    return value


def read_names(value: object, where: str, max_items: int) -> tuple[str, ...]:
    """A non-empty list of distinct channel names."""
    if not isinstance(value, list):
        raise InvalidField(INVALID_MESSAGE, where, f"must be a list, got {_kind(value)}")
    if not 1 <= len(value) <= max_items:
        raise InvalidField(
            INVALID_MESSAGE, where, f"must hold 1 to {max_items} names, got {len(value)}"
        )
    names = tuple(
        read_text(item, f"{where}[{index}]", MAX_NAME_LENGTH) for index, item in enumerate(value)
    )
    if len(set(names)) != len(names):
        raise InvalidField(INVALID_MESSAGE, where, "names must be distinct")
    return names


def read_bytes(value: object, where: str) -> bytes:
    """A msgpack ``bin``."""
    if not isinstance(value, bytes):
        raise InvalidField(
            INVALID_MESSAGE, where, f"must be binary (msgpack bin), got {_kind(value)}"
        )
    return value


def read_base64(value: object, where: str, code: str) -> bytes:
    """Standard padded base64 text (RFC 4648 section 4)."""
    if not isinstance(value, str):
        raise InvalidField(INVALID_MESSAGE, where, f"must be a base64 string, got {_kind(value)}")
    if not _BASE64.fullmatch(value):
        raise InvalidField(code, where, "must be standard padded base64")
    try:
        return base64.b64decode(value, validate=True)
    except (binascii.Error, ValueError):
        raise InvalidField(code, where, "is not decodable base64") from None


def read_json_map(value: object, where: str) -> dict[str, JsonValue]:
    """A free-form map of JSON values: string keys, finite numbers, 64-bit integers,
    at most ``MAX_MAP_ENTRIES`` entries per map and ``MAX_JSON_DEPTH`` levels."""
    if not isinstance(value, dict):
        raise InvalidField(INVALID_MESSAGE, where, f"must be an object, got {_kind(value)}")
    stack: list[tuple[object, str, int]] = [(value, where, 1)]
    while stack:
        node, path, depth = stack.pop()
        if isinstance(node, dict):
            stack.extend(_map_children(node, path, depth))
        elif isinstance(node, list):
            _check_depth(path, depth)
            stack.extend((item, f"{path}[{index}]", depth + 1) for index, item in enumerate(node))
        else:
            _check_scalar(node, path)
    return value


def _map_children(node: dict[Any, Any], path: str, depth: int) -> list[tuple[object, str, int]]:
    _check_depth(path, depth)
    if len(node) > MAX_MAP_ENTRIES:
        raise InvalidField(INVALID_MESSAGE, path, f"must have at most {MAX_MAP_ENTRIES} entries")
    children: list[tuple[object, str, int]] = []
    for key, item in node.items():
        if not isinstance(key, str):
            raise InvalidField(INVALID_MESSAGE, path, "object keys must be strings")
        read_text(key, f"{path} key", MAX_NAME_LENGTH, control=True)
        children.append((item, child(path, key), depth + 1))
    return children


def _check_depth(path: str, depth: int) -> None:
    if depth > MAX_JSON_DEPTH:
        raise InvalidField(INVALID_MESSAGE, path, f"nests deeper than {MAX_JSON_DEPTH} levels")


def _check_scalar(node: object, path: str) -> None:
    if node is None or isinstance(node, bool):
        return
    if isinstance(node, int):
        if not _INT64_MIN <= node <= _UINT64_MAX:
            raise InvalidField(INVALID_MESSAGE, path, "integers must fit in 64 bits")
    elif isinstance(node, float):
        if not math.isfinite(node):
            raise InvalidField(INVALID_MESSAGE, path, f"must be finite, got {node!r}")
    elif isinstance(node, str):
        require_utf8(node, path)
    else:
        raise InvalidField(INVALID_MESSAGE, path, f"must be a JSON value, got {_kind(node)}")


def require_utf8(value: str, where: str) -> None:
    if value.isascii():
        return
    try:
        value.encode("utf-8")
    except UnicodeEncodeError:
        raise InvalidField(
            INVALID_MESSAGE, where, "must be valid Unicode (no lone surrogates)"
        ) from None


def _as_float(value: float) -> float:
    try:
        return float(value)
    except OverflowError:
        return math.inf if value > 0 else -math.inf


def _kind(value: object) -> str:
    names = {
        type(None): "null",
        bool: "boolean",
        int: "integer",
        float: "number",
        str: "string",
        bytes: "binary",
        list: "list",
        dict: "object",
    }
    return names.get(type(value), type(value).__name__)
