"""Data tables written as text, parsed once at import.

Method: a name list is its text split on whitespace; a map is the same split
read two tokens at a time as (key, value). Rows and spacing are free, so a
table keeps the grouping a reader scans by (one row per class, place of
articulation, ...) without a formatter exemption. A key with no value or a
repeated key raises at import.
"""

from __future__ import annotations


def names(text: str) -> tuple[str, ...]:
    """The whitespace-separated names in ``text``, in order."""
    return tuple(text.split())


def pairs(text: str) -> dict[str, str]:
    """``text`` read as ``key value`` pairs separated by whitespace, in order."""
    tokens = text.split()
    if len(tokens) % 2:
        raise ValueError(f"table key {tokens[-1]!r} has no value")
    keys, values = tokens[::2], tokens[1::2]
    table = dict(zip(keys, values, strict=True))
    if len(table) != len(keys):
        repeated = sorted({key for key in keys if keys.count(key) > 1})
        raise ValueError(f"table keys repeat: {repeated}")
    return table
