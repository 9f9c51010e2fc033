"""The command line explains itself: a version, a help line for every option, the demo's paths."""

from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from lipstream._version import __version__
from lipstream.cli import _parser, main
from tests.helpers import run_cli


def _subcommands(
    parser: argparse.ArgumentParser, prefix: str = "lipstream"
) -> dict[str, argparse.ArgumentParser]:
    """Every (sub)command's parser by its command line, nested ones too."""
    found = {prefix: parser}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                found.update(_subcommands(sub, f"{prefix} {name}"))
    return found


def _undocumented(parser: argparse.ArgumentParser) -> list[str]:
    return [
        "/".join(action.option_strings) or action.dest
        for action in parser._actions
        if not isinstance(action, argparse._HelpAction | argparse._SubParsersAction)
        and not (action.help or "").strip()
    ]


def test_every_option_of_every_subcommand_has_help() -> None:
    commands = _subcommands(_parser())
    expected = (
        "build-demo",
        "train",
        "synth",
        "serve",
        "inspect",
        "bench",
        "loadtest",
        "bridge",
        "path",
    )
    assert {f"lipstream {name}" for name in expected} <= set(commands)
    assert {"lipstream loadtest capacity", "lipstream loadtest soak"} <= set(commands)
    missing = {name: _undocumented(sub) for name, sub in commands.items()}
    assert {name: options for name, options in missing.items() if options} == {}


def test_help_walk_finds_an_option_without_help() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--documented", help="says what it does")
    parser.add_argument("--bare")
    assert _undocumented(parser) == ["--bare"]


def test_version_prints_the_package_version(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exited:
        main(["--version"])
    assert exited.value.code == 0
    assert capsys.readouterr().out.strip() == f"lipstream {__version__}"
    assert __version__.count(".") == 2


@pytest.mark.parametrize("engine", ["viseme-lerp", "anime-graph"])
def test_path_demo_follows_lipstream_home(
    engine: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import lipstream

    monkeypatch.setenv("LIPSTREAM_HOME", str(tmp_path / "home"))
    expected = tmp_path / "home" / "demo" / "models" / engine
    assert lipstream.demo_model_path(engine) == expected
    result = run_cli("path", "demo", "--engine", engine)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == str(expected)
    whole = run_cli("path", "demo")
    assert whole.stdout.strip() == str(tmp_path / "home" / "demo" / "models")


def test_path_of_an_unknown_engine_is_a_clear_error() -> None:
    result = run_cli("path", "demo", "--engine", "nope")
    assert result.returncode == 2
    assert result.stderr.startswith("error [unknown_engine]: engine: unknown engine 'nope'")


def test_synth_with_a_missing_model_says_no_such_directory(tmp_path: Path) -> None:
    phones = tmp_path / "hello.lab"
    phones.write_text("0.0 0.1 HH\n0.1 0.3 AY\n")
    missing = tmp_path / "nowhere" / "viseme-lerp"
    result = run_cli(
        "synth", "--model", str(missing), "--phones", str(phones), "--out", str(tmp_path / "o.csv")
    )
    assert result.returncode == 2
    assert result.stderr.strip() == f"error [model_invalid]: {missing}: no such directory"
