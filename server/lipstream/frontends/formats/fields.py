"""Reading the JSON values of a timing input: one spelling or another of a key, lists and
objects, each failure an ``unknown_timing_format`` error naming the place."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from lipstream_client.errors import UNKNOWN_TIMING_FORMAT

from ...errors import LipstreamError


def misfit(message: str, where: str) -> LipstreamError:
    """The input does not have the shape its format has."""
    return LipstreamError(message, where=where, code=UNKNOWN_TIMING_FORMAT)


def mapping(value: Any, where: str) -> Mapping[str, Any]:
    if not isinstance(value, Mapping):
        raise misfit(f"expected an object, got {type(value).__name__}", where)
    return value


def array(value: Any, where: str) -> Sequence[Any]:
    if not isinstance(value, list | tuple):
        raise misfit(f"expected a list, got {type(value).__name__}", where)
    return value


def text(value: Any, where: str) -> str:
    if not isinstance(value, str):
        raise misfit(f"expected a string, got {type(value).__name__}", where)
    return value


def first_key(item: Mapping[str, Any], keys: Sequence[str]) -> str | None:
    """The first of ``keys`` (spellings of one field) that ``item`` has."""
    return next((key for key in keys if key in item), None)


def member(item: Mapping[str, Any], keys: Sequence[str], where: str) -> tuple[Any, str]:
    """The value of the first of ``keys`` in ``item`` and its place; a misfit naming the
    field when none is there."""
    key = first_key(item, keys)
    if key is None:
        raise misfit(f"lacks the field {keys[0]!r}", where)
    return item[key], f"{where}.{key}"
