"""The layers of docs/explanation/architecture.md, checked on the source: no module imports a
layer above its own (module-level, function-level and ``TYPE_CHECKING`` imports alike).

From the bottom: ``phonetics``; the vocabulary (``errors``, ``tables``, ``phonemes``,
``visemes``, ``timeline``); ``numerics``; ``engines``; ``output``; ``server``; then the
command line, benchmarks, load tools and training, which may use everything. ``recording``
(sessions of a visitor's recordings) is below the server, whose routes use it, except its
job, which runs in its own process and trains: only ``recording.job`` may import the
server, training and capture. The client SDK
(``lipstream_client``) is the protocol and stands apart: it imports no ``lipstream``.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SERVER = ROOT / "server" / "lipstream"
CLIENT = ROOT / "client_sdk" / "lipstream_client"
VOCABULARY = {"errors", "tables", "phonemes", "visemes", "timeline"}
ABOVE_SERVER = {"cli", "bench", "loadtest", "training", "deploy"}
FORBIDDEN: dict[str, set[str]] = {
    "phonetics": {"*"},
    **{name: {"*"} for name in VOCABULARY},
    "numerics": {"engines", "output", "server", "frontends", "speech", "capture", "demo"}
    | ABOVE_SERVER,
    "engines": {"output", "server", "frontends", "speech", "capture", "demo"} | ABOVE_SERVER,
    "output": {"server"} | ABOVE_SERVER,
    "frontends": {"engines", "output", "server", "capture"} | ABOVE_SERVER,
    "server": ABOVE_SERVER,
    "recording": {"server", "capture", "training", "cli", "bench", "loadtest", "deploy"},
}
JOB_MODULE = "lipstream.recording.job"


def package_of(module: str) -> str:
    """``lipstream.engines.dam.model`` -> ``engines``; ``lipstream.phonemes`` -> ``phonemes``."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def imported(path: Path, module: str) -> set[str]:
    """Every ``lipstream`` module ``path`` (the module ``module``) imports, anywhere in it."""
    package = module if path.name == "__init__.py" else module.rsplit(".", 1)[0]
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                name = ".".join(base + ([node.module] if node.module else []))
            else:
                name = node.module or ""
            found.add(name)
        elif isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
    return {name for name in found if name == "lipstream" or name.startswith("lipstream.")}


def violations(path: Path, module: str) -> list[str]:
    layer = package_of(module)
    forbidden = set() if module == JOB_MODULE else FORBIDDEN.get(layer, set())
    wrong = []
    for target in sorted(imported(path, module)):
        other = package_of(target)
        if other == layer or not other:
            continue
        if "*" in forbidden:
            allowed = VOCABULARY | {"phonetics"} if layer in VOCABULARY else set()
            if other not in allowed:
                wrong.append(target)
        elif other in forbidden:
            wrong.append(target)
    return wrong


def module_name(path: Path) -> str:
    parts = list(path.relative_to(SERVER.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


SOURCES = sorted(SERVER.rglob("*.py"))


@pytest.mark.parametrize("path", SOURCES, ids=lambda path: str(path.relative_to(SERVER)))
def test_no_module_imports_a_layer_above_its_own(path: Path) -> None:
    assert violations(path, module_name(path)) == []


@pytest.mark.parametrize("path", sorted(CLIENT.rglob("*.py")), ids=lambda path: path.name)
def test_the_client_sdk_imports_no_server_module(path: Path) -> None:
    assert imported(path, "lipstream_client." + path.stem) == set()


def test_the_check_sees_relative_lazy_and_type_checking_imports(tmp_path: Path) -> None:
    source = tmp_path / "kernels.py"
    source.write_text(
        "from typing import TYPE_CHECKING\n"
        "from ..timeline import PhonemeSpan\n"
        "if TYPE_CHECKING:\n"
        "    from ...output.profiles import Profile\n"
        "def lazy() -> None:\n"
        "    import lipstream.server.app\n"
        "    from .. import features\n"
    )
    module = "lipstream.engines.dam.kernels"
    assert violations(source, module) == ["lipstream.output.profiles", "lipstream.server.app"]
    assert violations(source, "lipstream.cli.kernels") == []
    vocabulary = tmp_path / "phonemes.py"
    vocabulary.write_text("from .phonetics import nearest_phoneme\nfrom .frontends import x\n")
    assert violations(vocabulary, "lipstream.phonemes") == ["lipstream.frontends"]
