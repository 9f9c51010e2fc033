"""``lipstream synth --words``: a TTS timing file drives a model from the command line; a
bad file is one coded line and exit status 2."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from lipstream.cli import main

pytestmark = pytest.mark.skipif(shutil.which("espeak-ng") is None, reason="espeak-ng missing")

POLLY = (
    '{"time":50,"type":"word","start":0,"end":4,"value":"Mary"}\n'
    '{"time":420,"type":"word","start":5,"end":8,"value":"had"}\n'
    '{"time":800,"type":"viseme","value":"sil"}\n'
)


def test_training_saves_the_duration_model_beside_the_model(lerp_model_dir: Path) -> None:
    assert {"model.json", "arrays.npz", "word_durations.json", "word_durations.npz"} <= {
        path.name for path in lerp_model_dir.iterdir()
    }


def test_synth_words_writes_frames_to_the_last_word(
    lerp_model_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    timings = tmp_path / "marks.txt"
    timings.write_text(POLLY, encoding="utf-8")
    out = tmp_path / "frames.json"
    status = main(
        [
            "synth",
            "--model",
            str(lerp_model_dir),
            "--words",
            str(timings),
            "--out",
            str(out),
            "--fps",
            "50",
        ]
    )
    assert status in (0, None)
    frames = json.loads(out.read_text(encoding="utf-8"))
    assert len(frames["frames"]) == round(0.8 * 50) + 1
    assert "wrote 41 frames" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("content", "expected"),
    [
        ('[{"word": "hi", "start": 0.5, "end": 0.2}]', "error [invalid_times]: {path}: words[0]:"),
        ('{"nothing": 1}', "error [unknown_timing_format]: {path}: input:"),
        ("", "error [empty_timings]: {path}:"),
    ],
)
def test_a_bad_timing_file_is_one_coded_line(
    lerp_model_dir: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    content: str,
    expected: str,
) -> None:
    timings = tmp_path / "bad.json"
    timings.write_text(content, encoding="utf-8")
    status = main(
        [
            "synth",
            "--model",
            str(lerp_model_dir),
            "--words",
            str(timings),
            "--out",
            str(tmp_path / "f.json"),
        ]
    )
    assert status == 2
    assert capsys.readouterr().err.startswith(expected.format(path=timings))


def test_a_model_without_a_duration_model_says_to_retrain(
    lerp_model_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    model = tmp_path / "old"
    shutil.copytree(lerp_model_dir, model)
    (model / "word_durations.json").unlink()
    timings = tmp_path / "words.json"
    timings.write_text('[{"word": "hi", "start": 0.1, "end": 0.4}]', encoding="utf-8")
    assert (
        main(
            [
                "synth",
                "--model",
                str(model),
                "--words",
                str(timings),
                "--out",
                str(tmp_path / "f.json"),
            ]
        )
        == 2
    )
    assert "retrain" in capsys.readouterr().err
