"""Every broken corpus raises CorpusError naming the file and the line (or key/column) at fault."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from lipstream.corpus import load_corpus
from lipstream.errors import CorpusError, UnknownPhonemeError


@pytest.fixture
def root(build: Any, tmp_path: Path) -> Path:
    """A valid two-utterance corpus (61 frames at 60 fps, phones to 1.0 s) to break."""
    build.write_utterance(tmp_path, "a")
    build.write_utterance(tmp_path, "b")
    load_corpus(tmp_path)  # valid before each test breaks it
    return tmp_path


def fails(root: Path, *fragments: str) -> str:
    with pytest.raises(CorpusError) as caught:
        load_corpus(root)
    message = str(caught.value)
    for fragment in fragments:
        assert fragment in message, f"{fragment!r} not in {message!r}"
    return message


# --- frame CSVs --------------------------------------------------------------


@pytest.mark.parametrize(
    ("cell", "reason"),
    [("nan", "finite"), ("inf", "finite"), ("abc", "not a number"), ("", "not a number")],
)
def test_bad_cell_names_line_and_column(build: Any, root: Path, cell: str, reason: str) -> None:
    path = root / "b.csv"
    fields = path.read_text().splitlines()[3].split(",")
    fields[2] = cell
    build.replace_line(path, 4, ",".join(fields))
    fails(root, "b.csv:line 4", "'mouthClose'", reason)


def test_non_increasing_time_names_line(build: Any, root: Path) -> None:
    path = root / "a.csv"
    fields = path.read_text().splitlines()[5].split(",")  # line 6 repeats line 5's time
    fields[0] = path.read_text().splitlines()[4].split(",")[0]
    build.replace_line(path, 6, ",".join(fields))
    fails(root, "a.csv:line 6", "increase strictly")


def test_first_time_must_be_zero(build: Any, root: Path) -> None:
    path = root / "a.csv"
    build.replace_line(path, 2, "0.001,0.1,0.5,-0.25")
    fails(root, "a.csv:line 2", "start at 0")


def test_missing_time_column(root: Path) -> None:
    path = root / "a.csv"
    path.write_text(path.read_text().replace("time,", "t,", 1))
    fails(root, "a.csv:line 1", "'time'")


def test_duplicate_column(root: Path) -> None:
    path = root / "b.csv"
    path.write_text(path.read_text().replace("mouthPucker", "jawOpen", 1))
    fails(root, "b.csv:line 1", "duplicate column 'jawOpen'")


def test_ragged_row(build: Any, root: Path) -> None:
    path = root / "a.csv"
    build.replace_line(path, 3, "0.0166666,0.1,0.2")
    fails(root, "a.csv:line 3", "3 cells", "4 columns")


def test_blank_line_inside_data(build: Any, root: Path) -> None:
    build.replace_line(root / "a.csv", 10, "")
    fails(root, "a.csv:line 10", "blank line")


def test_single_row_defines_no_rate(root: Path) -> None:
    (root / "a.csv").write_text("time,jawOpen,mouthClose,mouthPucker\n0,0.1,0.2,0.3\n")
    fails(root, "a.csv", "at least 2 data rows")


def test_empty_csv(root: Path) -> None:
    (root / "a.csv").write_text("")
    fails(root, "a.csv", "empty")


def test_channel_sets_differ(build: Any, root: Path) -> None:
    times = np.arange(61) / 60
    channels = ("jawOpen", "mouthClose", "cheekPuff")
    build.write_frames(root / "b.csv", times, build.linear_frames(times), channels)
    fails(root, "a.csv", "b.csv", "only in a.csv: mouthPucker", "only in b.csv: cheekPuff")


# --- phones ------------------------------------------------------------------


def test_phones_past_frames_end_by_more_than_a_frame(build: Any, root: Path) -> None:
    phones = [(0.0, 0.5, "AA"), (0.5, 1.0 + 1.5 / 60, "B")]
    path = root / "b.TextGrid"
    path.write_text(build.textgrid_long({"phones": phones}))
    line = build.line_of(path, f"xmax = {1.0 + 1.5 / 60}", occurrence=3)
    fails(root, f"b.TextGrid:line {line}", "past the end of the frames in b.csv")


def test_lab_phones_past_frames_end(root: Path) -> None:
    (root / "a.TextGrid").unlink()
    (root / "a.lab").write_text("0.0 0.5 sil\n0.5 1.5 AA\n")
    fails(root, "a.lab:line 2", "past the end")


def test_missing_phones_tier_lists_tiers(build: Any, root: Path) -> None:
    text = build.textgrid_long({"words": [(0, 1.0, "hi")], "phonemes": [(0, 1.0, "AA")]})
    (root / "a.TextGrid").write_text(text)
    fails(
        root,
        "a.TextGrid",
        "no phone tier ('phones', 'MAU', 'phone', 'segments'",
        "'words', 'phonemes'",
        "--tier",
    )


def test_overlapping_textgrid_intervals(build: Any, root: Path) -> None:
    path = root / "a.TextGrid"
    path.write_text(build.textgrid_long({"phones": [(0, 0.5, "AA"), (0.4, 1.0, "B")]}))
    line = build.line_of(path, "xmin = 0.4")
    fails(root, f"a.TextGrid:line {line}", "before the previous interval")


def test_textgrid_intervals_out_of_order(build: Any, root: Path) -> None:
    path = root / "a.TextGrid"  # praatio would quietly sort these two
    path.write_text(build.textgrid_long({"phones": [(0.5, 1.0, "B"), (0, 0.5, "AA")]}))
    line = build.line_of(path, "xmin = 0 ", occurrence=3)
    fails(root, f"a.TextGrid:line {line}", "before the previous interval")


def test_zero_length_textgrid_interval(build: Any, root: Path) -> None:
    path = root / "a.TextGrid"
    path.write_text(
        build.textgrid_long({"phones": [(0, 0.5, "AA"), (0.5, 0.5, "B"), (0.5, 1, "C")]})
    )
    line = build.line_of(path, "xmax = 0.5 ", occurrence=2)
    fails(root, f"a.TextGrid:line {line}", "not after its start")


def test_truncated_long_textgrid(build: Any, root: Path) -> None:
    path = root / "a.TextGrid"
    text = build.textgrid_long({"phones": build.PHONES})
    path.write_text(text[: text.index("intervals [3]")])
    fails(root, "a.TextGrid", "malformed TextGrid")


def test_truncated_short_textgrid_is_not_silently_shortened(build: Any, root: Path) -> None:
    path = root / "a.TextGrid"
    lines = build.textgrid_short({"phones": build.PHONES}).splitlines()
    path.write_text("\n".join(lines[:-3]) + "\n")  # praatio alone would return 3 intervals
    fails(root, f"a.TextGrid:line {len(lines) - 3}", "file ends")


def test_garbage_textgrid(root: Path) -> None:
    (root / "a.TextGrid").write_text("hello\n")
    fails(root, "a.TextGrid")


def test_overlapping_lab_intervals(root: Path) -> None:
    (root / "a.TextGrid").unlink()
    (root / "a.lab").write_text("0.0 0.5 sil\n0.5 0.8 AA\n0.7 1.0 B\n")
    fails(root, "a.lab:line 3", "before the previous interval")


@pytest.mark.parametrize(
    ("text", "line", "reason"),
    [
        ("0.0 0.5 sil\n0.5 x AA\n", 2, "not a number"),
        ("0.0 0.5 sil\n0.5 0.9\n", 2, "no label"),
        ("0.0 0.5 sil\n0.5 0.9 AA extra\n", 2, "4 fields"),
        ("0.5 sil\n0.5 0.9 AA\n", 2, "mixes line forms"),
        ("0.0 0.5 sil\n0.5 0.5 AA\n", 2, "not after its start"),
        ("signal x\n#\n0.5 121 sil\n", 2, "ESPS"),
        ("-0.1 0.5 sil\n", 1, "before 0"),
    ],
)
def test_broken_lab_lines(root: Path, text: str, line: int, reason: str) -> None:
    (root / "a.TextGrid").unlink()
    (root / "a.lab").write_text(text)
    fails(root, f"a.lab:line {line}", reason)


def test_empty_lab(root: Path) -> None:
    (root / "a.TextGrid").unlink()
    (root / "a.lab").write_text("\n\n")
    fails(root, "a.lab", "no phone intervals")


def test_unknown_phoneme_names_file_and_line(root: Path) -> None:
    (root / "a.TextGrid").unlink()
    (root / "a.lab").write_text("0.0 0.5 sil\n0.5 1.0 QQQ\n")
    with pytest.raises(UnknownPhonemeError, match=r"a\.lab:line 2.*QQQ"):
        load_corpus(root)


# --- layout ------------------------------------------------------------------


def test_phones_without_frames(build: Any, root: Path) -> None:
    (root / "c.TextGrid").write_text(build.textgrid_long({"phones": build.PHONES}))
    fails(root, "'c'", "no frames file c.csv")


def test_frames_without_phones(root: Path) -> None:
    (root / "b.TextGrid").unlink()
    fails(root, "'b'", "no phones file")


def test_audio_without_frames(root: Path) -> None:
    (root / "z.wav").write_bytes(b"")
    fails(root, "'z'", "no frames file")


def test_two_phones_files(root: Path) -> None:
    (root / "a.lab").write_text("0 1 sil\n")
    fails(root, "'a'", "a.TextGrid and a.lab")


def test_empty_corpus(tmp_path: Path) -> None:
    (tmp_path / "notes.txt").write_text("nothing here")
    fails(tmp_path, str(tmp_path), "empty corpus")


def test_not_a_directory(tmp_path: Path) -> None:
    fails(tmp_path / "missing", "missing", "not a directory")


# --- corpus.json and <stem>.json ----------------------------------------------


@pytest.mark.parametrize(
    ("config", "fragments"),
    [
        ({"fps": 60, "speed": 2}, ("corpus.json", "unknown key 'speed'")),
        ({"fps": "60"}, ("corpus.json", "'fps'", "number")),
        ({"fps": True}, ("corpus.json", "'fps'")),
        ({"fps": -5}, ("corpus.json", "'fps'", "positive")),
        ({"name": 3}, ("corpus.json", "'name'")),
        ({"channels": "jawOpen"}, ("corpus.json", "'channels'", "list")),
        ({"channels": []}, ("corpus.json", "'channels'", "at least one")),
        ({"channels": ["jawOpen", "jawOpen"]}, ("corpus.json", "'channels'", "more than once")),
        ({"channels": ["jawOpen", "browDownLeft"]}, ("corpus.json", "'channels'", "browDownLeft")),
        ({"heldout": ["a", "zzz"]}, ("corpus.json", "'heldout'", "zzz")),
        ({"heldout": [1]}, ("corpus.json", "'heldout'")),
        ([1, 2], ("corpus.json", "object")),
    ],
)
def test_bad_corpus_json(root: Path, config: object, fragments: tuple[str, ...]) -> None:
    (root / "corpus.json").write_text(json.dumps(config))
    fails(root, *fragments)


def test_corpus_json_syntax_error_names_line(root: Path) -> None:
    (root / "corpus.json").write_text('{\n  "fps": 60,\n  "name": oops\n}\n')
    fails(root, "corpus.json:line 3", "invalid JSON")


@pytest.mark.parametrize(
    ("metadata", "fragment"),
    [
        ({"emotion": "bored"}, "'emotion'"),
        ({"emotion": 1}, "'emotion'"),
        ({"speaker": 7}, "'speaker'"),
        ({"text": ["hi"]}, "'text' must be a string"),
    ],
)
def test_bad_utterance_metadata(root: Path, metadata: dict[str, object], fragment: str) -> None:
    (root / "b.json").write_text(json.dumps(metadata))
    fails(root, "b.json", fragment)


def test_error_code_and_where_are_structured(build: Any, root: Path) -> None:
    path = root / "a.csv"
    fields = path.read_text().splitlines()[6].split(",")
    build.replace_line(path, 7, f"{fields[0]},0.1,nan,0.2")
    with pytest.raises(CorpusError) as caught:
        load_corpus(root)
    assert caught.value.code == "corpus_invalid"
    assert caught.value.where == "a.csv:line 7"
    assert re.search(r"column 'mouthClose'", caught.value.message)
