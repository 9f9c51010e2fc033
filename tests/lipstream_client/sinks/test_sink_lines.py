"""JSON lines and CSV on a stream: parsed back, values the float32s sent, channel order kept."""

from __future__ import annotations

import csv
import io
import json
import struct

from lipstream_client.sinks import LinesSink

NAMES = ["jawOpen", "mouthClose", "A"]
ROWS = [[0.1, 0.2, 0.3], [0.40000001, 1.0, 0.0]]


def float32(value: float) -> float:
    return float(struct.unpack("<f", struct.pack("<f", value))[0])


def test_json_lines() -> None:
    out = io.StringIO()
    sink = LinesSink(out, "jsonl")
    sink.open(NAMES, 60.0)
    for index, row in enumerate(ROWS):
        sink.send(index, index / 60.0, [float32(value) for value in row])
    lines = [json.loads(line) for line in out.getvalue().splitlines()]
    assert [line["frame"] for line in lines] == [0, 1]
    assert lines[1]["time"] == round(1 / 60, 6)
    for line, row in zip(lines, ROWS):
        assert list(line["values"]) == NAMES
        assert [float32(v) for v in line["values"].values()] == [float32(v) for v in row]
    assert '"jawOpen":0.1,' in out.getvalue()  # the fewest digits that read back


def test_csv() -> None:
    out = io.StringIO()
    sink = LinesSink(out, "csv")
    sink.open(NAMES, 60.0)
    for index, row in enumerate(ROWS):
        sink.send(index, index / 60.0, [float32(value) for value in row])
    table = list(csv.reader(io.StringIO(out.getvalue())))
    assert table[0] == ["frame", "time", *NAMES]
    assert [int(line[0]) for line in table[1:]] == [0, 1]
    assert [[float32(float(v)) for v in line[2:]] for line in table[1:]] == [
        [float32(v) for v in row] for row in ROWS
    ]


class ClosedPipe(io.StringIO):
    def write(self, text: str) -> int:
        raise BrokenPipeError(32, "Broken pipe")


def test_a_reader_that_went_away_is_counted() -> None:
    sink = LinesSink(ClosedPipe(), "jsonl")
    sink.open(NAMES, 60.0)
    for index, row in enumerate(ROWS):
        sink.send(index, index / 60.0, row)
    sink.close()
    assert (sink.delivery().sent, sink.delivery().failed) == (0, 2)
