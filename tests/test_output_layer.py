"""The output layer sits below the server and the command line: nothing in ``lipstream.output``
imports ``lipstream.server`` or ``lipstream.cli``, at module level or inside a function.

Each module's syntax tree is read with ``ast``; relative imports are resolved against the
module's package, so ``from ..server import x`` counts as well as the absolute form.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from tests.helpers import REPO

PACKAGE_ROOT = REPO / "server"
OUTPUT = PACKAGE_ROOT / "lipstream" / "output"
ABOVE = ("lipstream.server", "lipstream.cli")


def module_name(path: Path, root: Path) -> str:
    parts = path.relative_to(root).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imported_modules(path: Path, root: Path = PACKAGE_ROOT) -> list[str]:
    """Every module ``path`` (under the import root ``root``) imports: for ``from m import
    n``, both ``m`` and ``m.n``, since ``n`` may be a module."""
    package = module_name(path, root)
    if path.name != "__init__.py":
        package = package.rpartition(".")[0]
    found: list[str] = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                anchor = parts[: len(parts) - node.level + 1]
                base = ".".join([*anchor, base] if base else anchor)
            found += [base, *(f"{base}.{alias.name}" for alias in node.names)]
    return found


def is_above(module: str) -> bool:
    return any(module == layer or module.startswith(layer + ".") for layer in ABOVE)


def test_relative_imports_resolve_to_the_modules_they_name(tmp_path: Path) -> None:
    written = tmp_path / "lipstream" / "output" / "case.py"
    written.parent.mkdir(parents=True)
    written.write_text(
        "from ..server import catalog\n"
        "from . import visemes\n"
        "def lazy() -> None:\n"
        "    import lipstream.cli.main\n"
    )
    modules = imported_modules(written, tmp_path)
    assert modules == [
        "lipstream.server",
        "lipstream.server.catalog",
        "lipstream.output",
        "lipstream.output.visemes",
        "lipstream.cli.main",
    ]
    assert [module for module in modules if is_above(module)] == [
        "lipstream.server",
        "lipstream.server.catalog",
        "lipstream.cli.main",
    ]


@pytest.mark.parametrize("path", sorted(OUTPUT.rglob("*.py")), ids=lambda p: p.name)
def test_the_output_layer_imports_neither_the_server_nor_the_cli(path: Path) -> None:
    assert [module for module in imported_modules(path) if is_above(module)] == []


def test_the_server_and_the_cli_find_output_profiles_in_the_output_layer() -> None:
    """The moved modules are gone from the server package, so nothing imports them there."""
    server = PACKAGE_ROOT / "lipstream" / "server"
    assert not (server / "profiles.py").exists()
    assert not (server / "viseme_projection.py").exists()
    assert (OUTPUT / "profiles.py").exists() and (OUTPUT / "viseme_projection.py").exists()
