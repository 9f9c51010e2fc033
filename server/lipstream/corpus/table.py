"""Strict CSV tables with line numbers, shared by the frame readers.

Sketch: read the file with the ``csv`` module (quoting, BOM and CRLF handled),
keep each data row with its 1-based editor line, reject duplicate or blank
header names, ragged rows and blank lines inside the data, then convert
columns to float64 in one go; only when that fails (or yields NaN/inf) scan
the cells to name every bad one by line and column. A file's ragged rows are
all named too.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple, TextIO

import numpy as np

from ..errors import CorpusError, LipstreamError
from .validation import MAX_PROBLEMS, at_line, raise_each


class FrameTable(NamedTuple):
    """Frames as read from a file, before resampling.

    ``times``: (n,) seconds, strictly increasing. ``frames``: (n, c) float32.
    ``channels``: the c column names, in file order.
    """

    times: np.ndarray
    frames: np.ndarray
    channels: tuple[str, ...]


@dataclass(frozen=True)
class CsvTable:
    """A CSV file's header and data rows; ``lines[k]`` is the editor line of ``rows[k]``."""

    path: Path
    header: tuple[str, ...]
    rows: list[list[str]]
    lines: list[int]

    def where(self, line: int) -> str:
        return at_line(self.path.name, line)

    def column_index(self, name: str) -> int:
        return self.header.index(name)

    def text_column(self, name: str) -> list[str]:
        index = self.column_index(name)
        return [row[index] for row in self.rows]

    def numeric_columns(self, names: tuple[str, ...]) -> np.ndarray:
        """The named columns as float64, shape (n_rows, len(names)).

        Cells must be finite numbers.
        """
        indices = [self.column_index(name) for name in names]
        cells = [[row[i] for i in indices] for row in self.rows]
        try:
            values = np.array(cells, dtype=np.float64).reshape(len(self.rows), len(names))
        except ValueError:
            values = None
        if values is None or not np.all(np.isfinite(values)):
            raise_each(self._bad_cells(names, indices), where=self.path.name)
        assert values is not None
        return values

    def _bad_cells(self, names: tuple[str, ...], indices: list[int]) -> list[LipstreamError]:
        """Every cell of the named columns that is not a finite number, by line and column,
        up to one more than ``MAX_PROBLEMS``."""
        bad: list[LipstreamError] = []
        for row, line in zip(self.rows, self.lines):
            for name, index in zip(names, indices):
                cell = row[index]
                try:
                    finite = bool(np.isfinite(float(cell)))
                    message = f"column {name!r}: {cell.strip()!r} is not a finite number"
                except ValueError:
                    finite, message = False, f"column {name!r}: {cell!r} is not a number"
                if not finite:
                    bad.append(CorpusError(message, where=self.where(line)))
                if len(bad) > MAX_PROBLEMS:
                    return bad
        return bad


def read_csv_table(path: Path) -> CsvTable:
    """Read ``path`` into a ``CsvTable``; raise ``CorpusError`` naming file:line on bad shape."""
    try:
        with open(path, encoding="utf-8-sig", newline="") as handle:
            numbered = _numbered_rows(handle, path)
    except OSError as exc:
        raise CorpusError(f"cannot read file: {exc.strerror}", where=str(path)) from None
    except UnicodeDecodeError:
        raise CorpusError("file is not UTF-8 text", where=path.name) from None
    if not numbered:
        raise CorpusError("file is empty", where=path.name)
    header_line, raw_header = numbered[0]
    header = tuple(cell.strip() for cell in raw_header)
    _check_header(path, header_line, header)
    body = _strip_trailing_blank(numbered[1:])
    problems: list[LipstreamError] = []
    for line, row in body:
        if not row:
            problems.append(
                CorpusError("blank line inside the data", where=at_line(path.name, line))
            )
        elif len(row) != len(header):
            problems.append(
                CorpusError(
                    f"row has {len(row)} cells but the header has {len(header)} columns",
                    where=at_line(path.name, line),
                )
            )
        if len(problems) > MAX_PROBLEMS:
            break
    raise_each(problems, where=path.name)
    return CsvTable(path, header, [row for _, row in body], [line for line, _ in body])


def _numbered_rows(handle: TextIO, path: Path) -> list[tuple[int, list[str]]]:
    reader = csv.reader(handle, strict=True)
    numbered: list[tuple[int, list[str]]] = []
    previous_end = 0
    try:
        for row in reader:
            numbered.append((previous_end + 1, row))
            previous_end = reader.line_num
    except csv.Error as exc:
        raise CorpusError(
            f"malformed CSV: {exc}", where=at_line(path.name, reader.line_num)
        ) from None
    return numbered


def _strip_trailing_blank(rows: list[tuple[int, list[str]]]) -> list[tuple[int, list[str]]]:
    end = len(rows)
    while end > 0 and not rows[end - 1][1]:
        end -= 1
    return rows[:end]


def _check_header(path: Path, line: int, header: tuple[str, ...]) -> None:
    where = at_line(path.name, line)
    if not header:
        raise CorpusError("the first line must be the header, found a blank line", where=where)
    for position, name in enumerate(header, start=1):
        if not name:
            raise CorpusError(f"header column {position} has no name", where=where)
    seen: set[str] = set()
    for name in header:
        if name in seen:
            raise CorpusError(f"duplicate column {name!r} in the header", where=where)
        seen.add(name)
