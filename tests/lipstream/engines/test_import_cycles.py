"""The engines' modules import one another without a circle, counting every import a module
names: at its top, inside functions, and under ``if TYPE_CHECKING:``.

The graph is read from the source with ``ast`` (nothing is imported); an edge goes to the
module an import names; ``from package import name`` goes to ``package.name`` when that is
a submodule, to ``package`` (its ``__init__``) when some name is not. A package's
``__init__`` being run before its submodules is not an edge.
"""

from __future__ import annotations

import ast
from pathlib import Path

from tests.helpers import REPO

ENGINES = REPO / "server" / "lipstream" / "engines"


def module_names(root: Path, package: str) -> dict[str, Path]:
    """Every module under ``root`` (the directory of ``package``) by dotted name."""
    names = {}
    for path in sorted(root.rglob("*.py")):
        parts = list(path.relative_to(root).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        names[".".join([package, *parts])] = path
    return names


def imported(module: str, path: Path, known: dict[str, Path]) -> set[str]:
    """The modules of ``known`` that ``module`` (at ``path``) imports anywhere in its text."""
    is_package = path.name == "__init__.py"
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = module.split(".")
                keep = len(parts) - node.level + (1 if is_package else 0)
                base = ".".join(parts[:keep] + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            submodules = [f"{base}.{alias.name}" for alias in node.names]
            named = [name for name in submodules if name in known]
            targets = named if len(named) == len(submodules) else [base, *named]
        else:
            continue
        found.update(target for target in targets if target in known and target != module)
    return found


def import_cycles(root: Path, package: str) -> list[list[str]]:
    """Each circle of imports among the modules under ``root``, as the modules on it."""
    known = module_names(root, package)
    graph = {module: imported(module, path, known) for module, path in known.items()}
    cycles: list[list[str]] = []
    state: dict[str, str] = {}
    trail: list[str] = []

    def visit(module: str) -> None:
        state[module] = "open"
        trail.append(module)
        for target in sorted(graph[module]):
            if state.get(target) == "open":
                cycles.append(trail[trail.index(target) :] + [target])
            elif target not in state:
                visit(target)
        trail.pop()
        state[module] = "done"

    for module in sorted(graph):
        if module not in state:
            visit(module)
    return cycles


def test_no_engine_module_imports_itself_round_a_circle() -> None:
    assert import_cycles(ENGINES, "lipstream.engines") == []


def test_a_circle_closed_under_type_checking_is_found(tmp_path: Path) -> None:
    package = tmp_path / "engine"
    package.mkdir()
    (package / "__init__.py").write_text("from .model import Model\n")
    (package / "model.py").write_text("from .synthesizer import Synthesizer\n")
    (package / "tables.py").write_text("import numpy\n")
    (package / "synthesizer.py").write_text(
        "from typing import TYPE_CHECKING\n"
        "from . import tables\n"
        "if TYPE_CHECKING:\n"
        "    from .model import Model\n"
    )
    assert import_cycles(package, "engine") == [
        ["engine.model", "engine.synthesizer", "engine.model"]
    ]
    (package / "synthesizer.py").write_text("from . import tables\n")
    assert import_cycles(package, "engine") == []


def test_a_circle_through_a_function_level_import_is_found(tmp_path: Path) -> None:
    package = tmp_path / "engine"
    (package / "inner").mkdir(parents=True)
    (package / "__init__.py").write_text("")
    (package / "inner" / "__init__.py").write_text("")
    (package / "inner" / "a.py").write_text("from ..b import thing\n")
    (package / "b.py").write_text("def thing():\n    from engine.inner import a\n")
    assert import_cycles(package, "engine") == [["engine.b", "engine.inner.a", "engine.b"]]
