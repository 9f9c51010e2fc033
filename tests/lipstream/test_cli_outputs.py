"""Measuring commands write their results under ``$LIPSTREAM_HOME/bench`` unless given a
``--results`` path, never into the current directory unasked (it may be a checkout whose
``bench/*.json`` are committed measurements)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from lipstream import cli
from lipstream.config import load_settings
from tests.lipstream_client.fake_server import FakeServer

COMMANDS = [
    (["bench"], "results.json"),
    (["bench", "--real"], "real_faces.json"),
    (["loadtest"], "loadtest.json"),
    (["loadtest", "capacity", "--engine", "hmm", "--character", "demo"], "capacity.json"),
    (["loadtest", "soak"], "soak.json"),
]


@pytest.fixture
def work(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """An empty current directory, with ``$LIPSTREAM_HOME`` elsewhere."""
    directory = tmp_path / "work"
    directory.mkdir()
    monkeypatch.chdir(directory)
    monkeypatch.setenv("LIPSTREAM_HOME", str(tmp_path / "home"))
    return directory


@pytest.mark.parametrize(("argv", "name"), COMMANDS)
def test_no_results_option_means_a_file_under_lipstream_home(
    argv: list[str], name: str, tmp_path: Path
) -> None:
    args = cli._parser().parse_args(argv)
    assert args.results is None
    settings = load_settings({"LIPSTREAM_HOME": str(tmp_path)})
    assert settings.results_file(args.results, name) == tmp_path / "bench" / name
    given = str(tmp_path / "mine.json")
    assert settings.results_file(given, name) == tmp_path / "mine.json"


@pytest.mark.parametrize(("argv", "name"), COMMANDS)
def test_help_names_the_default_file(
    argv: list[str], name: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit):
        cli._parser().parse_args([*argv[: 2 if argv[0] == "loadtest" else 1], "--help"])
    assert f"$LIPSTREAM_HOME/bench/{name}" in " ".join(capsys.readouterr().out.split())


def test_loadtest_writes_under_lipstream_home_and_says_where(
    work: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with FakeServer() as server:
        status = cli.main(
            [
                "loadtest",
                "--url",
                server.url,
                "--engine",
                "viseme-lerp",
                "--character",
                "demo",
                "--streams",
                "1",
                "--requests",
                "1",
                "--clips",
                "1",
                "--pause",
                "0",
            ]
        )
    assert status == 0
    written = tmp_path / "home" / "bench" / "loadtest.json"
    assert json.loads(written.read_text())["summary"]["requests"] == 1
    assert list(work.iterdir()) == []
    assert f"results written to {written}" in capsys.readouterr().err


def test_bench_writes_under_lipstream_home_and_says_where(
    work: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import lipstream.bench.harness
    import lipstream.corpus

    corpora: list[Path] = []
    measured = {"engines": {"viseme-lerp": {"rms": 0.25}}}

    def load_corpus(directory: Path, **options: Any) -> str:
        corpora.append(Path(directory))
        return "corpus"

    def run_bench(corpus: str, **options: Any) -> dict[str, Any]:
        assert corpus == "corpus"
        return measured

    monkeypatch.setattr(lipstream.corpus, "load_corpus", load_corpus)
    monkeypatch.setattr(lipstream.bench.harness, "run_bench", run_bench)
    assert cli.main(["bench", "--corpus", str(tmp_path / "corpus"), "--json"]) == 0
    assert corpora == [tmp_path / "corpus"]
    written = tmp_path / "home" / "bench" / "results.json"
    assert json.loads(written.read_text()) == measured
    assert list(work.iterdir()) == []
    assert f"wrote {written}" in capsys.readouterr().err


def test_bench_writes_to_the_current_directory_when_asked(
    work: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import lipstream.bench.harness
    import lipstream.corpus

    monkeypatch.setattr(lipstream.corpus, "load_corpus", lambda directory, **options: "corpus")
    monkeypatch.setattr(lipstream.bench.harness, "run_bench", lambda corpus, **options: {"n": 1})
    assert cli.main(["bench", "--corpus", "c", "--json", "--results", "out.json"]) == 0
    assert json.loads((work / "out.json").read_text()) == {"n": 1}
    assert not (tmp_path / "home").exists()
