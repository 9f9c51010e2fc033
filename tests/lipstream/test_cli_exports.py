"""``lipstream train``/``synth`` with aligner tiers, output profiles and animators' formats."""

from __future__ import annotations

import csv
import json
import re
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pytest

from lipstream.corpus.livelink import read_livelink_csv
from lipstream.timeline import PhonemeSpan
from tests.helpers import run_cli

if TYPE_CHECKING:
    from lipstream.engines.base import Model

# "ma" in WebMAUS SAMPA: a pause, m (shape A), A: (shape D), a pause.
MAU = [(0.0, 0.3, "<p:>"), (0.3, 0.5, "m"), (0.5, 0.9, "A:"), (0.9, 1.2, "<p:>")]
SPANS = [
    PhonemeSpan("sil", 0.0, 0.3),
    PhonemeSpan("M", 0.3, 0.5),
    PhonemeSpan("AA", 0.5, 0.9),
    PhonemeSpan("sil", 0.9, 1.2),
]


def textgrid(tiers: dict[str, list[tuple[float, float, str]]]) -> str:
    xmax = max(tier[-1][1] for tier in tiers.values())
    lines = ['File type = "ooTextFile"', 'Object class = "TextGrid"', "", "0", str(xmax)]
    lines += ["<exists>", str(len(tiers))]
    for name, intervals in tiers.items():
        lines += ['"IntervalTier"', f'"{name}"', "0", str(xmax), str(len(intervals))]
        for start, end, label in intervals:
            lines += [str(start), str(end), f'"{label}"']
    return "\n".join(lines) + "\n"


@pytest.fixture(scope="module")
def lerp_model(trained_models: dict[str, Model], tmp_path_factory: pytest.TempPathFactory) -> Path:
    directory = tmp_path_factory.mktemp("cli-exports") / "viseme-lerp"
    trained_models["viseme-lerp"].save(directory)
    return directory


@pytest.fixture(scope="module")
def mau_grid(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("cli-phones") / "ma.TextGrid"
    path.write_text(textgrid({"ORT-MAU": [(0.0, 1.2, "ma")], "MAU": MAU}))
    return path


def synth(model: Path, phones: Path, out: Path, *extra: str) -> str:
    result = run_cli(
        "synth", "--model", str(model), "--phones", str(phones), "--out", str(out), *extra
    )
    assert result.returncode == 0, result.stderr
    return out.read_text()


def test_rhubarb_tsv_from_a_webmaus_textgrid(
    lerp_model: Path, mau_grid: Path, tmp_path: Path
) -> None:
    text = synth(lerp_model, mau_grid, tmp_path / "ma.tsv", "--fps", "50")
    lines = text.splitlines()
    assert all(re.fullmatch(r"\d+\.\d\d\t[A-HX]", line) for line in lines)
    starts = [float(line.split("\t")[0]) for line in lines]
    shapes = [line.split("\t")[1] for line in lines]
    assert starts == sorted(starts) and starts[0] == 0.0 and lines[-1] == "1.22\tX"

    def shape_at(t: float) -> str:
        return shapes[max(i for i, start in enumerate(starts) if start <= t)]

    # Held phones show their own shape at their centres: X, A (M), D (AA), X.
    assert [shape_at(t) for t in (0.15, 0.4, 0.7, 1.1)] == ["X", "A", "D", "X"]


def test_xml_json_and_moho_come_from_the_same_cues(
    lerp_model: Path, mau_grid: Path, tmp_path: Path
) -> None:
    tsv = synth(lerp_model, mau_grid, tmp_path / "ma.tsv", "--fps", "50").splitlines()
    cues = json.loads(
        synth(lerp_model, mau_grid, tmp_path / "ma.json", "--fps", "50", "--format", "rhubarb-json")
    )
    assert [f"{cue['start']:.2f}\t{cue['value']}" for cue in cues["mouthCues"]] == tsv[:-1]
    assert cues["metadata"] == {"soundFile": "", "duration": 1.22}
    xml = synth(lerp_model, mau_grid, tmp_path / "ma.xml", "--fps", "50")
    assert xml.count("<mouthCue ") == len(tsv) - 1
    dat = synth(lerp_model, mau_grid, tmp_path / "ma.dat", "--fps", "50").splitlines()
    assert dat[0] == "MohoSwitch1" and dat[1] == "1 X" and dat[-1].endswith(" X")
    # 24 fps Moho frames: the end (1.22 s) is frame 1 + floor(29.28) = 30.
    assert dat[-1] == "30 X"


def test_live_link_export_round_trips_the_models_frames(
    lerp_model: Path, mau_grid: Path, tmp_path: Path, trained_models: dict[str, Model]
) -> None:
    out = tmp_path / "ma.csv"
    synth(lerp_model, mau_grid, out, "--fps", "60", "--format", "livelink")
    table = read_livelink_csv(out)
    model = trained_models["viseme-lerp"]
    expected = model.synthesize(SPANS, fps=60.0)
    np.testing.assert_allclose(table.times, np.arange(len(expected.frames)) / 60, atol=2e-5)
    for name in ("jawOpen", "mouthClose", "mouthPucker"):
        column = expected.frames[:, model.channels.index(name)]
        np.testing.assert_allclose(table.frames[:, table.channels.index(name)], column, atol=1e-9)


def test_profiles_from_a_file_and_flags(lerp_model: Path, mau_grid: Path, tmp_path: Path) -> None:
    profile = tmp_path / "profile.json"
    profile.write_text(json.dumps({"naming": "livelink", "channels": ["JawOpen", "MouthClose"]}))
    out = synth(lerp_model, mau_grid, tmp_path / "a.csv", "--profile", str(profile))
    assert out.splitlines()[0] == "time,JawOpen,MouthClose"
    out = synth(
        lerp_model, mau_grid, tmp_path / "b.csv", "--profile", str(profile), "--channels", "JawOpen"
    )
    assert out.splitlines()[0] == "time,JawOpen"
    out = synth(
        lerp_model, mau_grid, tmp_path / "c.csv", "--visemes", "preston-blair", "--fps", "50"
    )
    rows = list(csv.reader(out.splitlines()))
    assert rows[0] == ["time", "A", "B", "C", "D", "E", "F", "G", "H", "X"]
    weights = np.array([[float(cell) for cell in row[1:]] for row in rows[1:]])
    np.testing.assert_allclose(weights.sum(axis=1), 1.0, atol=1e-5)
    assert rows[0][1 + int(np.argmax(weights[20]))] == "A"  # 0.4 s, the centre of M


@pytest.mark.parametrize(
    ("extra", "code", "fragment"),
    [
        (("--visemes", "oculus15", "--naming", "livelink"), "invalid_setting", "'naming' applies"),
        (
            ("--tier", "phones"),
            "corpus_invalid",
            "no tier named 'phones'; tiers found: 'ORT-MAU', 'MAU'",
        ),
        (("--channels", "nose"), "unknown_channel", "profile.channels[0]"),
        (("--format", "moho", "--visemes", "oculus15"), "invalid_request", "nine Preston Blair"),
    ],
)
def test_bad_synth_requests_are_one_coded_line(
    lerp_model: Path,
    mau_grid: Path,
    tmp_path: Path,
    extra: tuple[str, ...],
    code: str,
    fragment: str,
) -> None:
    out = tmp_path / "x.csv"
    result = run_cli(
        "synth", "--model", str(lerp_model), "--phones", str(mau_grid), "--out", str(out), *extra
    )
    assert result.returncode == 2
    assert f"error [{code}]" in result.stderr and fragment in result.stderr
    assert "Traceback" not in result.stderr


def test_train_reads_the_tier_named_on_the_command_line(tmp_path: Path) -> None:
    corpus = tmp_path / "corpus"
    corpus.mkdir()
    times = np.arange(73) / 60
    for stem in ("a", "b"):
        with open(corpus / f"{stem}.csv", "w", newline="") as handle:
            writer = csv.writer(handle)
            writer.writerow(["time", "jawOpen", "mouthClose"])
            writer.writerows([t, 0.5 * t, 1 - 0.5 * t] for t in times)
        (corpus / f"{stem}.TextGrid").write_text(textgrid({"KAN": MAU}))
    (corpus / "a.json").write_text(json.dumps({"text": "ma", "note": "take 2"}))
    out = tmp_path / "model"
    refused = run_cli(
        "train", "--corpus", str(corpus), "--engine", "viseme-lerp", "--out", str(out)
    )
    assert (
        refused.returncode == 2 and "no phone tier" in refused.stderr and "'KAN'" in refused.stderr
    )
    trained = run_cli(
        "train",
        "--corpus",
        str(corpus),
        "--engine",
        "viseme-lerp",
        "--out",
        str(out),
        "--tier",
        "KAN",
    )
    assert trained.returncode == 0, trained.stderr
    assert "warning: a.json: unknown key 'note' ignored" in trained.stderr
    assert json.loads((out / "model.json").read_text())["channels"] == ["jawOpen", "mouthClose"]


def test_a_profile_file_that_is_not_a_profile_object_is_refused(
    lerp_model: Path, mau_grid: Path, tmp_path: Path
) -> None:
    profile = tmp_path / "profile.json"
    profile.write_text("[1, 2]")
    result = run_cli(
        "synth",
        "--model",
        str(lerp_model),
        "--phones",
        str(mau_grid),
        "--out",
        str(tmp_path / "x.csv"),
        "--profile",
        str(profile),
    )
    assert result.returncode == 2
    assert "error [invalid_setting]" in result.stderr
    assert "must be a JSON object holding an output profile" in result.stderr
