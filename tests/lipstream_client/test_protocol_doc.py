"""docs/reference/protocol.md stays complete: its examples decode, and it names every type, field and code."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from lipstream_client import ERROR_CODES, CloseCode, ProtocolError, decode, load_schema
from lipstream_client.messages import MESSAGE_TYPES

DOC = (Path(__file__).resolve().parents[2] / "docs" / "reference" / "protocol.md").read_text(
    encoding="utf-8"
)
EXAMPLES = re.findall(r"```json\n(.*?)```", DOC, flags=re.DOTALL)


def section(message_type: str) -> str:
    match = re.search(rf"^### `{message_type}`\n(.*?)(?=^##)", DOC, flags=re.DOTALL | re.MULTILINE)
    assert match, f"no section for {message_type}"
    return match.group(1)


def test_every_json_example_is_a_valid_message() -> None:
    decoded = [decode(example, "json") for example in EXAMPLES]
    assert [result for result in decoded if isinstance(result, ProtocolError)] == []
    messages = [result for result in decoded if not isinstance(result, ProtocolError)]
    assert {message.type for message in messages} == set(MESSAGE_TYPES)


@pytest.mark.parametrize("message_type", sorted(MESSAGE_TYPES))
def test_every_schema_field_is_documented_in_its_section(message_type: str) -> None:
    text = section(message_type)
    fields = set(load_schema(message_type)["properties"]) - {"v", "type"}
    assert sorted(field for field in fields if not re.search(rf"`{field}(`|\.|\[\]\.)", text)) == []


@pytest.mark.parametrize(
    ("message_type", "definition", "prefix"),
    [
        ("phonemes", "phonemeItem", "items[]."),
        ("done", "stats", "stats."),
        ("start", "output", ""),
        ("start", "transform", ""),
    ],
)
def test_nested_fields_are_documented(message_type: str, definition: str, prefix: str) -> None:
    fields = load_schema(message_type)["$defs"][definition]["properties"]
    assert sorted(field for field in fields if f"`{prefix}{field}`" not in DOC) == []


def test_every_error_code_has_a_row_with_its_close_code() -> None:
    for code, info in ERROR_CODES.items():
        row = re.search(rf"^\| `{code}` \|(.*)$", DOC, flags=re.MULTILINE)
        assert row, f"error code {code} is not in the table"
        cells = [cell.strip() for cell in row.group(1).split("|")]
        assert cells[1] == info.scope, code
        assert cells[2] == (str(int(info.close_code)) if info.close_code else ""), code


def test_every_close_code_has_a_row() -> None:
    for close_code in CloseCode:
        assert re.search(rf"^\| {int(close_code)} \|", DOC, flags=re.MULTILINE), close_code


def test_subprotocols_and_version_rule_are_stated() -> None:
    for phrase in (
        "lipstream.v1.msgpack",
        "lipstream.v1.json",
        "```mermaid",
        '"v": 1',
        "lipstream.v2.msgpack",
    ):
        assert phrase in DOC
