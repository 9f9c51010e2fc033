"""Key-pose pairs as CSV: one row per pose, read into and written from the JSON document.

Sketch: a spreadsheet is the natural place to write key poses, so
``lipstream retarget`` also takes ``.csv`` pairs files (docs/how-to/retarget.md).
The header is ``name`` and then one column per value: ``source.<channel>`` for
a model channel, ``controls.<control>`` for a rig control (the controls are
these columns, in order). Each row is a key pose named in its first cell;
two reserved names hold the rest pose (``@rest``) and the channel weights
(``@weight``, source columns only). An empty cell names nothing, so the
value falls back as in the JSON form (rest, or weight 1). ``csv_document``
turns the rows into the JSON document's structure, so both forms are checked
by the same code and their errors name the same fields (``keys[i]`` is the
i-th key row); only the table's own shape (header, row lengths) is checked
here. ``document_csv`` writes a document back as such a table.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Mapping, Sequence
from typing import Any

from ..model_checks import FieldReader

NAME_COLUMN = "name"
SOURCE_PREFIX = "source."
CONTROL_PREFIX = "controls."
REST_ROW = "@rest"
WEIGHT_ROW = "@weight"


def _cell(text: str) -> Any:
    """A number where the cell holds one; else the text, which the pose check refuses
    naming its field."""
    try:
        return float(text)
    except ValueError:
        return text


def _columns(fields: FieldReader, header: Sequence[str]) -> list[tuple[str, str]]:
    """(part, name) of each value column: part ``source`` or ``controls``."""
    if not header or header[0].strip() != NAME_COLUMN:
        raise fields.error("header", f"the first column must be {NAME_COLUMN!r}")
    columns = []
    for title in (text.strip() for text in header[1:]):
        if title.startswith(SOURCE_PREFIX) and len(title) > len(SOURCE_PREFIX):
            columns.append(("source", title[len(SOURCE_PREFIX) :]))
        elif title.startswith(CONTROL_PREFIX) and len(title) > len(CONTROL_PREFIX):
            columns.append(("controls", title[len(CONTROL_PREFIX) :]))
        else:
            raise fields.error(
                "header",
                f"column {title!r} must be {SOURCE_PREFIX}<channel> or {CONTROL_PREFIX}<control>",
            )
    if len(set(columns)) != len(columns):
        raise fields.error("header", "a column is repeated")
    return columns


def csv_document(text: str, where: str) -> dict[str, Any]:
    """The pairs document (as the JSON form holds it) of a CSV pairs table."""
    fields = FieldReader(where)
    rows = [row for row in csv.reader(io.StringIO(text)) if any(cell.strip() for cell in row)]
    if not rows:
        raise fields.error("header", "the file holds no header")
    columns = _columns(fields, rows[0])
    document: dict[str, Any] = {
        "controls": [name for part, name in columns if part == "controls"],
        "rest": {"source": {}, "controls": {}},
        "keys": [],
        "channel_weights": {},
    }
    for number, row in enumerate(rows[1:], start=2):
        if len(row) != len(columns) + 1:
            raise fields.error(
                f"row {number}", f"has {len(row)} cells, the header {len(columns) + 1}"
            )
        name = row[0].strip()
        pose: dict[str, dict[str, Any]] = {"source": {}, "controls": {}}
        for (part, column), text in zip(columns, row[1:], strict=True):
            if text.strip():
                pose[part][column] = _cell(text.strip())
        if name == REST_ROW:
            document["rest"] = pose
        elif name == WEIGHT_ROW:
            if pose["controls"]:
                raise fields.error(f"row {number}", "weights apply to source columns only")
            document["channel_weights"] = pose["source"]
        else:
            document["keys"].append({"name": name, **pose})
    return document


def document_csv(document: Mapping[str, Any], channels: Sequence[str]) -> str:
    """A CSV pairs table of ``document`` (the JSON form's structure) for ``channels``."""
    controls = list(document["controls"])
    header = [
        NAME_COLUMN,
        *(SOURCE_PREFIX + name for name in channels),
        *(CONTROL_PREFIX + name for name in controls),
    ]

    def row(name: str, source: Mapping[str, float], values: Mapping[str, float]) -> list[str]:
        return [
            name,
            *(repr(source[c]) if c in source else "" for c in channels),
            *(repr(values[c]) if c in values else "" for c in controls),
        ]

    rest = document["rest"]
    lines = [header, row(REST_ROW, rest["source"], rest["controls"])]
    lines.extend(row(key["name"], key["source"], key["controls"]) for key in document["keys"])
    lines.append(row(WEIGHT_ROW, document["channel_weights"], {}))
    out = io.StringIO()
    csv.writer(out, lineterminator="\n").writerows(lines)
    return out.getvalue()
