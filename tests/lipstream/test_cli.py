"""The ``lipstream`` command line on a corpus another tool wrote: Live Link Face CSV + TextGrid.

The Live Link Face takes are written by the test in the app's format; with
``LIPSTREAM_LIVELINK_DIR`` set, the real exports form a second corpus.
"""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from lipstream.engines.base import frame_count
from tests.helpers import real_livelink_takes, run_cli, textgrid_long
from tests.livelink_takes import TAKES, write_take

PHONES = ["HH", "AH0", "L", "OW1", "W", "ER1", "L", "D", "M", "AA1", "P", "S", "IY1"]


def _phone_intervals(duration: float, seed: int) -> list[tuple[float, float, str]]:
    rng = np.random.default_rng(seed)
    intervals, cursor = [(0.0, 0.5, "")], 0.5
    while cursor < duration - 1.0:
        end = round(cursor + float(rng.uniform(0.05, 0.2)), 3)
        intervals.append((cursor, end, PHONES[int(rng.integers(len(PHONES)))]))
        cursor = end
    intervals.append((cursor, round(duration - 0.2, 3), "sp"))
    return intervals


REAL_TAKE_PHONES_S = 29.0  # the real exports run about 30 s


def _takes(source: str, root: Path) -> list[tuple[Path, float]]:
    """(CSV in ``root``, seconds to cover with phones) of each take of ``source``."""
    if source == "synthetic":
        return [(write_take(root, take), take.span_s - 0.1) for take in TAKES]
    copies = [Path(shutil.copy(path, root / path.name)) for path in real_livelink_takes()]
    return [(copy, REAL_TAKE_PHONES_S) for copy in copies]


@pytest.fixture(scope="module", params=["synthetic", *(["real"] if real_livelink_takes() else [])])
def livelink_corpus(
    request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
) -> Path:
    root = tmp_path_factory.mktemp(f"livelink_corpus_{request.param}")
    for seed, (source, phones_s) in enumerate(_takes(request.param, root)):
        (root / source.with_suffix(".TextGrid").name).write_text(
            textgrid_long(_phone_intervals(phones_s, seed))
        )
        (root / source.with_suffix(".json").name).write_text(
            json.dumps({"emotion": ["sad", "angry"][seed % 2], "speaker": "capture"})
        )
    return root


@pytest.mark.parametrize("engine", ["viseme-lerp", "anime-graph"])
def test_train_inspect_synth_on_livelink_textgrid_corpus(
    livelink_corpus: Path, tmp_path: Path, engine: str
) -> None:
    model_dir = tmp_path / "model"
    trained = run_cli(
        "train", "--corpus", str(livelink_corpus), "--engine", engine, "--out", str(model_dir)
    )
    assert trained.returncode == 0, trained.stderr
    manifest = json.loads((model_dir / "model.json").read_text())
    assert manifest["engine"] == engine and manifest["fps"] == 60.0
    assert "jawOpen" in manifest["channels"] and "JawOpen" not in manifest["channels"]

    inspected = run_cli("inspect", str(model_dir))
    assert inspected.returncode == 0 and f"engine {engine}" in inspected.stdout

    phones = tmp_path / "hello.json"
    phones.write_text(
        json.dumps(
            [
                {"phoneme": "HH", "start": 0.1, "end": 0.2},
                {"phoneme": "AH0", "start": 0.2, "end": 0.3},
                {"phoneme": "L", "start": 0.3, "end": 0.4},
                {"phoneme": "OW1", "start": 0.4, "end": 0.7},
            ]
        )
    )
    out = tmp_path / "hello.csv"
    synth = run_cli(
        "synth",
        "--model",
        str(model_dir),
        "--phones",
        str(phones),
        "--fps",
        "30",
        "--out",
        str(out),
    )
    assert synth.returncode == 0, synth.stderr
    with open(out, newline="") as handle:
        rows = list(csv.reader(handle))
    assert rows[0] == ["time", *manifest["channels"]]
    assert len(rows) - 1 == frame_count(0.7, 30.0)
    assert float(rows[2][0]) == pytest.approx(1 / 30, abs=1e-6)


def test_train_all_writes_one_directory_per_engine(livelink_corpus: Path, tmp_path: Path) -> None:
    from lipstream.engines import engine_names

    result = run_cli(
        "train",
        "--corpus",
        str(livelink_corpus),
        "--engine",
        "all",
        "--out",
        str(tmp_path / "models"),
    )
    assert result.returncode == 0, result.stderr
    assert sorted(p.name for p in (tmp_path / "models").iterdir()) == sorted(engine_names())


def test_broken_corpus_is_one_line_naming_file_and_line(
    livelink_corpus: Path, tmp_path: Path
) -> None:
    broken = tmp_path / "broken"
    shutil.copytree(livelink_corpus, broken)
    victim = min(broken.glob("*.csv"))
    lines = victim.read_text().splitlines()
    cells = lines[41].split(",")
    cells[20] = "nan"
    lines[41] = ",".join(cells)
    victim.write_text("\n".join(lines) + "\n")
    result = run_cli(
        "train", "--corpus", str(broken), "--engine", "viseme-lerp", "--out", str(tmp_path / "m")
    )
    assert result.returncode == 2
    message = result.stderr.strip().splitlines()
    assert len(message) == 1 or "Traceback" not in result.stderr
    assert victim.name in result.stderr and "42" in result.stderr
    assert "Traceback" not in result.stderr


def test_unknown_engine_and_missing_model_are_clear_errors(tmp_path: Path) -> None:
    result = run_cli("train", "--corpus", str(tmp_path), "--engine", "nope", "--out", "x")
    assert result.returncode == 2 and "unknown_engine" in result.stderr
    result = run_cli("inspect", str(tmp_path / "missing"))
    assert result.returncode == 2 and "model_invalid" in result.stderr
    assert "Traceback" not in result.stderr
