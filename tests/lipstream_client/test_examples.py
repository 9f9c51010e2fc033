"""The client examples (client_sdk/examples) run against a real server with a bounded runtime."""

from __future__ import annotations

import importlib.util
import json
import os
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from lipstream.engines.base import Model
from tests.helpers import REPO, return_frames, run_cli, textgrid_long
from tests.live_server import LiveServer, live_server, save_models

EXAMPLES = REPO / "client_sdk" / "examples"
RUNTIME_LIMIT_S = 40


def canned_line() -> list[tuple[str, float, float]]:
    spec = importlib.util.spec_from_file_location("examples_shared", EXAMPLES / "_shared.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    line: list[tuple[str, float, float]] = module.CANNED_LINE
    return line


@pytest.fixture(scope="module")
def served(
    trained_models: dict[str, Model], tmp_path_factory: pytest.TempPathFactory
) -> Iterator[LiveServer]:
    with live_server(save_models(trained_models, tmp_path_factory.mktemp("models"))) as server:
        yield server


def run_example(name: str, *args: str) -> subprocess.CompletedProcess[str]:
    path = os.pathsep.join(
        [str(REPO / "server"), str(REPO / "client_sdk"), os.environ.get("PYTHONPATH", "")]
    )
    return subprocess.run(
        [sys.executable, str(EXAMPLES / name), *args],
        capture_output=True,
        text=True,
        timeout=RUNTIME_LIMIT_S,
        check=False,
        env={**os.environ, "PYTHONPATH": path},
    )


def test_game_loop_plays_every_frame(served: LiveServer, trained_models: dict[str, Model]) -> None:
    result = run_example("game_loop.py", "--url", served.ws, "--report-every", "0.5")
    assert result.returncode == 0, result.stderr
    character_engine = re.search(
        r"^(\S+)/demo: (\d+) channels at 60 fps", result.stdout, re.MULTILINE
    )
    assert character_engine is not None, result.stdout
    model = trained_models[character_engine.group(1)]
    assert int(character_engine.group(2)) == len(model.channels)
    # The line's frames, then the return to rest (150 ms at 60 fps).
    expected = len(model.synthesize(canned_line(), fps=60.0).frames) + return_frames(60.0)
    summary = re.search(
        r"(\d+) frames received; (\d+) late ticks; done: end, (\d+) frames", result.stdout
    )
    assert summary is not None, result.stdout
    assert int(summary.group(1)) == int(summary.group(3)) == expected
    assert result.stdout.count("t=") >= 3
    assert re.search(r"server max lag \d+\.\d ms$", result.stdout, re.MULTILINE), result.stdout


def test_chat_avatar_streams_replies_and_handles_barge_in(served: LiveServer) -> None:
    # The server's default engine: for one that reads audio, audio must lead the input.
    result = run_example(
        "chat_avatar.py",
        "--url",
        served.ws,
        "--send-audio",
        "--interrupt-at",
        "0.4",
        "--text",
        "Hello there, nice to meet you.",
        "--text",
        "Goodbye.",
    )
    assert result.returncode == 0, result.stderr
    dones = re.findall(r"done: (\w+)", result.stdout)
    assert dones == ["interrupt", "end"], result.stdout
    latencies = re.findall(r"first frame after (\S+ ms) \(server\)", result.stdout)
    assert len(latencies) == 2 and all(re.fullmatch(r"\d+\.\d ms", v) for v in latencies)
    assert "reply 2: 'Goodbye.'" in result.stdout  # spoken by espeak-ng, not the canned line
    # The default engine and lead: viseme-lerp, which then never waits for input.
    assert result.stdout.startswith("viseme-lerp/demo, each phoneme sent 400 ms before")


def test_chat_avatar_lead_outlasts_every_phoneme_of_its_replies() -> None:
    """viseme-lerp's frame waits for the phoneme after its own, so a lead longer than every
    phoneme of the speech means no frame waits for input."""
    # In a process of its own: the example drives libespeak-ng in-process, and this test
    # process has already driven it through other voices and threads.
    script = (
        "import json, chat_avatar as c\n"
        "spans = [s for t in c.DEFAULT_REPLIES for s in c.speak(t, 'en-us').spans]\n"
        "print(json.dumps([c.DEFAULT_ENGINE, c.DEFAULT_LEAD_MS, len(spans),"
        " max(end - start for _, start, end in spans)]))\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", script],
        cwd=EXAMPLES,
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    )
    engine, lead_ms, count, longest = json.loads(result.stdout.splitlines()[-1])
    assert engine == "viseme-lerp" and count > 20
    assert 0.2 < longest < lead_ms / 1000.0


def test_phones_to_csv_matches_lipstream_synth(served: LiveServer, tmp_path: Path) -> None:
    intervals = [(0.0, 0.1, "sil"), (0.1, 0.2, "HH"), (0.2, 0.45, "AY1"), (0.45, 0.6, "")]
    (tmp_path / "hi.TextGrid").write_text(textgrid_long(intervals), encoding="utf-8")
    (tmp_path / "mam.lab").write_text(
        "0 0.1 sil\n0.1 0.2 M\n0.2 0.4 AA\n0.4 0.5 M\n", encoding="utf-8"
    )
    (tmp_path / "few.json").write_text(
        json.dumps(
            [
                {"phoneme": "F", "start": 0.0, "end": 0.1},
                {"phoneme": "UW", "start": 0.1, "end": 0.3},
            ]
        ),
        encoding="utf-8",
    )
    sources = ["hi.TextGrid", "mam.lab", "few.json"]
    result = run_example(
        "phones_to_csv.py",
        "--url",
        served.ws,
        "--engine",
        "viseme-lerp",
        "--character",
        "demo",
        "--out-dir",
        str(tmp_path / "out"),
        *(str(tmp_path / name) for name in sources),
        str(tmp_path / "missing.lab"),
    )
    assert result.returncode == 1  # one input is missing; the others still convert
    assert "converted 3 of 4 files" in result.stdout
    assert "missing.lab" in result.stderr
    for name in sources:
        reference = tmp_path / f"{Path(name).stem}.reference.csv"
        synth = run_cli(
            "synth",
            "--model",
            str(served.models_dir / "viseme-lerp"),
            "--phones",
            str(tmp_path / name),
            "--fps",
            "60",
            "--out",
            str(reference),
        )
        assert synth.returncode == 0, synth.stderr
        converted = (tmp_path / "out" / name).with_suffix(".csv")
        lines = converted.read_text(encoding="utf-8").splitlines()
        expected = reference.read_text(encoding="utf-8").splitlines()
        # The offline frames, then the server's return to rest: 150 ms at 60 fps.
        assert len(lines) == len(expected) + return_frames(60.0)
        assert lines[: len(expected)] == expected
