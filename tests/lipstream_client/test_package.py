"""The package imports without numpy, and its channel-name helpers follow the documented rules."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from lipstream_client import (
    OCULUS15_VISEMES,
    PRESTON_BLAIR_SHAPES,
    VISEME_CHANNELS,
    canonical_viseme,
    rename_channel,
)
from lipstream_client.messages import Naming

CLIENT_SDK = Path(__file__).resolve().parents[2] / "client_sdk"
PROTOCOL_DOC = Path(__file__).resolve().parents[2] / "docs" / "reference" / "protocol.md"
WITHOUT_NUMPY = """
import sys
sys.modules["numpy"] = None
import lipstream_client as client
from lipstream_client import schema, channels
message = client.Frames.from_rows("a", 0, 0, 60.0, [[0.25, 0.5]])
for encoding in ("msgpack", "json"):
    assert client.decode(client.encode(message, encoding), encoding) == message
assert schema.load_schema("frames")["$id"] == "urn:lipstream:protocol:v1:frames"
print("ok")
"""
NOT_LOADED = "import sys, lipstream_client; print(sorted(m for m in ('numpy', 'hypothesis') if m in sys.modules))"

WITHOUT_IO = """
import sys
sys.modules["websockets"] = None  # any import of websockets now fails
import lipstream_client.codec, lipstream_client.messages
from lipstream_client import Frames, decode, encode, ERROR_CODES
message = Frames.from_rows("a", 0, 0, 60.0, [[0.25]])
assert decode(encode(message, "json"), "json") == message and ERROR_CODES
loaded = ("asyncio", "lipstream_client.client", "lipstream_client.sync", "lipstream_client.rest")
print(sorted(name for name in loaded if name in sys.modules))
"""
LAZY_CLIENTS = """
import sys, lipstream_client
assert "lipstream_client.client" not in sys.modules
from lipstream_client import AsyncClient, Client
from lipstream_client.client import AsyncClient as Direct
assert AsyncClient is Direct and Client.__module__ == "lipstream_client.sync"
assert "websockets" in sys.modules
try:
    lipstream_client.NoSuchName
except AttributeError as error:
    print(error)
"""


def run_python(code: str) -> subprocess.CompletedProcess[str]:
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(CLIENT_SDK), os.environ.get("PYTHONPATH", "")]),
    }
    return subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        env=env,
        timeout=60,
        check=False,
    )


def test_imports_and_round_trips_with_numpy_blocked() -> None:
    result = run_python(WITHOUT_NUMPY)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "ok"


def test_import_loads_neither_numpy_nor_hypothesis() -> None:
    result = run_python(NOT_LOADED)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "[]"


def test_the_protocol_core_imports_without_websockets_or_asyncio() -> None:
    result = run_python(WITHOUT_IO)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "[]"


def test_the_clients_are_imported_on_first_use() -> None:
    result = run_python(LAZY_CLIENTS)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "module 'lipstream_client' has no attribute 'NoSuchName'"


@pytest.mark.parametrize(
    ("arkit", "naming", "expected"),
    [
        ("jawOpen", "arkit", "jawOpen"),
        ("jawOpen", "livelink", "JawOpen"),
        ("eyeBlinkLeft", "livelink", "EyeBlinkLeft"),
        ("eyeBlinkLeft", "suffix_lr", "eyeBlink_L"),
        ("mouthSmileRight", "suffix_lr", "mouthSmile_R"),
        ("jawOpen", "suffix_lr", "jawOpen"),
        ("leftEyeYaw", "suffix_lr", "leftEyeYaw"),
        ("Left", "suffix_lr", "Left"),
    ],
)
def test_rename_channel(arkit: str, naming: Naming, expected: str) -> None:
    assert rename_channel(arkit, naming) == expected


def test_oculus_visemes_order_and_spellings() -> None:
    assert len(OCULUS15_VISEMES) == 15
    assert OCULUS15_VISEMES[0] == "viseme_sil" and OCULUS15_VISEMES[-3:] == (
        "viseme_I",
        "viseme_O",
        "viseme_U",
    )
    assert OCULUS15_VISEMES.index("viseme_aa") == 10
    for spelling, canonical in [
        ("ih", "viseme_I"),
        ("oh", "viseme_O"),
        ("ou", "viseme_U"),
        ("viseme_I", "viseme_I"),
        ("I", "viseme_I"),
        ("viseme_ih", "viseme_I"),
        ("PP", "viseme_PP"),
        ("viseme_sil", "viseme_sil"),
        ("sil", "viseme_sil"),
    ]:
        assert canonical_viseme(spelling) == canonical
    for stranger in ("viseme_X", "jawOpen", "pp", "", "viseme_"):
        assert canonical_viseme(stranger) is None


def documented_preston_blair_order() -> tuple[str, ...]:
    """The shapes in the column order docs/reference/protocol.md gives, each a letter
    followed by its description: `A` (closed: P B M), `B` (...), ..."""
    text = PROTOCOL_DOC.read_text(encoding="utf-8")
    paragraph = text.split("**Preston Blair mouth shapes**", 1)[1].split("\n\n", 1)[0]
    return tuple(re.findall(r"`([A-Z])` \(", paragraph))


def test_preston_blair_shapes_and_spellings() -> None:
    # Rhubarb Lip Sync's six basic shapes A-F, then its extended G, H and X, as documented.
    assert documented_preston_blair_order() == (*"ABCDEF", "G", "H", "X")
    assert PRESTON_BLAIR_SHAPES == documented_preston_blair_order()
    assert VISEME_CHANNELS == {"oculus15": OCULUS15_VISEMES, "preston-blair": PRESTON_BLAIR_SHAPES}
    assert [canonical_viseme(name, "preston-blair") for name in ("a", "X", " h ")] == [
        "A",
        "X",
        "H",
    ]
    for stranger in ("I", "viseme_PP", "AB", "", "MBP"):
        assert canonical_viseme(stranger, "preston-blair") is None
