"""Settings from ``LIPSTREAM_*``: parsing, validation, and the documented table."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from dataclasses import fields
from pathlib import Path

import pytest

from lipstream.config import (
    ENV_SETTINGS,
    ServerSettings,
    load_server_settings,
    load_settings,
    server_setting_fields,
)
from lipstream.errors import LipstreamError
from tests.helpers import REPO

SERVER_DOC = (REPO / "docs" / "reference" / "server.md").read_text(encoding="utf-8")


def test_an_empty_environment_gives_the_defaults(tmp_path: Path) -> None:
    settings = load_settings({"LIPSTREAM_HOME": str(tmp_path)})
    assert (settings.host, settings.port, settings.models) == (
        "127.0.0.1",
        8000,
        tmp_path / "demo" / "models",
    )
    assert settings.server == ServerSettings()


def test_values_are_parsed_into_their_types() -> None:
    server = load_server_settings(
        {
            "LIPSTREAM_MAX_SESSIONS": " 5 ",
            "LIPSTREAM_MESSAGE_RATE": "2.5",
            "LIPSTREAM_AUTH_TOKENS": "alpha, beta,,",
            "LIPSTREAM_ALLOWED_ORIGINS": "",
            "LIPSTREAM_PROFILES": "/etc/lipstream/profiles.json",
            "LIPSTREAM_LOG_LEVEL": "DEBUG",
            "LIPSTREAM_DRAIN_TIMEOUT_S": "0",
            "LIPSTREAM_STRICT_MODELS": " Yes ",
        }
    )
    assert server.max_sessions == 5 and server.message_rate == 2.5
    assert server.auth_tokens == ("alpha", "beta") and server.allowed_origins == ()
    assert server.profiles == Path("/etc/lipstream/profiles.json")
    assert server.log_level == "debug" and server.drain_timeout_s == 0.0
    assert server.strict_models is True
    assert load_server_settings({"LIPSTREAM_STRICT_MODELS": "off"}).strict_models is False


@pytest.mark.parametrize(
    ("variable", "value", "expected"),
    [
        ("LIPSTREAM_MAX_SESSIONS", "0", "an integer in [1, 1000000]"),
        ("LIPSTREAM_MAX_SESSIONS", "many", "an integer"),
        ("LIPSTREAM_MESSAGE_RATE", "0", "a number in (0, 1e+09]"),
        ("LIPSTREAM_IDLE_TIMEOUT_S", "nan", "a number in (0, 1e+09]"),
        ("LIPSTREAM_LOG_LEVEL", "loud", "one of critical"),
        ("LIPSTREAM_STRICT_MODELS", "maybe", "one of 1, true, yes, on, 0, false, no, off"),
        ("LIPSTREAM_PORT", "70000", "an integer in [0, 65535]"),
    ],
)
def test_bad_values_name_the_variable(variable: str, value: str, expected: str) -> None:
    with pytest.raises(LipstreamError) as error:
        load_settings({variable: value})
    assert (error.value.code, error.value.where) == ("invalid_setting", variable)
    assert expected in error.value.message


def test_every_server_setting_has_one_variable() -> None:
    assert sorted(setting.field for setting in ENV_SETTINGS) == sorted(server_setting_fields())
    variables = [setting.variable for setting in ENV_SETTINGS]
    assert len(set(variables)) == len(variables)
    assert all(variable.startswith("LIPSTREAM_") for variable in variables)


def _shown(value: object) -> str:
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, tuple):
        return "(empty)" if not value else ",".join(map(str, value))
    if value is None:
        return "(none)"
    return f"{value:g}" if isinstance(value, float) else str(value)


def test_docs_list_every_variable_with_its_default() -> None:
    defaults = {item.name: item.default for item in fields(ServerSettings)}
    for setting in ENV_SETTINGS:
        row = re.search(rf"^\| `{setting.variable}` \| `([^`]*)` \|", SERVER_DOC, re.MULTILINE)
        assert row, f"{setting.variable} is not in the settings table of docs/reference/server.md"
        assert row.group(1) == _shown(defaults[setting.field]), setting.variable


def test_the_cli_reports_a_bad_setting_in_one_line(tmp_path: Path) -> None:
    result = subprocess.run(
        [sys.executable, "-m", "lipstream.cli", "serve", "--models", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
        env={**os.environ, "LIPSTREAM_MAX_SESSIONS": "lots"},
    )
    assert result.returncode == 2
    assert result.stderr.strip() == (
        "error [invalid_setting]: LIPSTREAM_MAX_SESSIONS: must be an integer, got 'lots'"
    )
