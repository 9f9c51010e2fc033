"""One load reports every problem of a corpus, each with its file and line, up to a limit."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from lipstream.corpus import load_corpus
from lipstream.corpus.validation import MAX_PROBLEMS
from lipstream.errors import CorpusError, CorpusProblems


def _broken_corpus(build: Any, root: Path) -> list[tuple[str, str]]:
    """Five utterances and a corpus.json with seven problems in six files; the expected
    (where, fragment) of each, in the order the loader meets them (corpus.json, then stems
    in sorted order, each stem's frames before its phones)."""
    for stem in "abcde":
        build.write_utterance(root, stem)
    load_corpus(root)  # valid before it is broken
    (root / "corpus.json").write_text(json.dumps({"heldout": ["a", "zz"]}))
    expected = [("corpus.json", "'heldout' names stems with no utterance: zz")]

    a_rows = (root / "a.csv").read_text().splitlines()
    for line, column, cell in ((4, 2, "abc"), (7, 1, "nan")):
        fields = a_rows[line - 1].split(",")
        fields[column] = cell
        build.replace_line(root / "a.csv", line, ",".join(fields))
    expected += [
        ("a.csv:line 4", "column 'mouthClose': 'abc' is not a number"),
        ("a.csv:line 7", "column 'jawOpen': 'nan' is not a finite number"),
    ]

    build.replace_line(root / "b.csv", 5, "0.0666,0.1")
    expected.append(("b.csv:line 5", "row has 2 cells but the header has 4 columns"))
    phones = [(0.0, 0.5, "AA"), (0.4, 1.0, "B")]
    (root / "b.TextGrid").write_text(build.textgrid_long({"phones": phones}))
    overlap = build.line_of(root / "b.TextGrid", "xmin = 0.4")
    expected.append((f"b.TextGrid:line {overlap}", "before the previous interval"))

    (root / "c.TextGrid").unlink()
    (root / "c.lab").write_text("0.0 0.5 sil\n0.5 1.5 AA\n")
    expected.append(("c.lab:line 2", "past the end of the frames in c.csv"))

    times = [k / 60 for k in range(61)]
    channels = ("jawOpen", "mouthClose", "cheekPuff")
    build.write_frames(root / "e.csv", times, build.linear_frames(times), channels)
    expected.append(("e.csv", "only in e.csv: cheekPuff"))
    return expected


def test_every_problem_is_reported_with_its_file_and_line(build: Any, tmp_path: Path) -> None:
    expected = _broken_corpus(build, tmp_path)
    with pytest.raises(CorpusProblems) as caught:
        load_corpus(tmp_path)
    error = caught.value
    assert (error.code, error.where, error.more) == ("corpus_invalid", str(tmp_path), False)
    assert [problem.where for problem in error.problems] == [where for where, _ in expected]
    for problem, (where, fragment) in zip(error.problems, expected):
        assert fragment in problem.message, (where, problem.message)
        assert problem.code == "corpus_invalid"
        assert f"{where}: {problem.message} [corpus_invalid]" in str(error)


def test_the_command_line_lists_every_problem(build: Any, tmp_path: Path) -> None:
    (tmp_path / "corpus").mkdir()
    expected = _broken_corpus(build, tmp_path / "corpus")
    finished = subprocess.run(
        [sys.executable, "-m", "lipstream.cli", "train", "--corpus", str(tmp_path / "corpus")]
        + ["--engine", "viseme-lerp", "--out", str(tmp_path / "model")],
        capture_output=True,
        text=True,
        check=False,
    )
    assert finished.returncode == 2
    lines = finished.stderr[finished.stderr.index("error [") :].strip().splitlines()
    assert lines[0] == f"error [corpus_invalid]: {tmp_path / 'corpus'}: {len(expected)} problems:"
    assert [line.split(": ")[0].strip() for line in lines[1:]] == [w for w, _ in expected]
    assert not (tmp_path / "model").exists()


def test_one_problem_is_raised_as_itself(build: Any, tmp_path: Path) -> None:
    for stem in "ab":
        build.write_utterance(tmp_path, stem)
    build.replace_line(tmp_path / "b.csv", 5, "0.0666,0.1")
    with pytest.raises(CorpusError) as caught:
        load_corpus(tmp_path)
    assert not isinstance(caught.value, CorpusProblems)
    assert caught.value.where == "b.csv:line 5"


def test_the_report_stops_at_the_limit(build: Any, tmp_path: Path) -> None:
    build.write_utterance(tmp_path, "a", duration=4.0)  # 241 frames
    rows = (tmp_path / "a.csv").read_text().splitlines()
    bad_lines = range(2, 2 + MAX_PROBLEMS + 20)
    for line in bad_lines:
        fields = rows[line - 1].split(",")
        fields[3] = "x"
        rows[line - 1] = ",".join(fields)
    (tmp_path / "a.csv").write_text("\n".join(rows) + "\n")
    with pytest.raises(CorpusProblems) as caught:
        load_corpus(tmp_path)
    error = caught.value
    assert error.more
    assert [problem.where for problem in error.problems] == [
        f"a.csv:line {line}" for line in bad_lines[:MAX_PROBLEMS]
    ]
    assert f"{MAX_PROBLEMS} problems, stopped at the first {MAX_PROBLEMS}:" in error.message
