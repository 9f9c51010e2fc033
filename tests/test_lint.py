"""ruff runs on the code: a lint finding anywhere in the packages or tests fails the suite.
Two house rules ruff has no check for are read from the source here: no formatter
exemption comments, and no function over twelve parameters."""

from __future__ import annotations

import ast
import importlib
import io
import re
import subprocess
import sys
import tokenize
from collections.abc import Callable
from pathlib import Path

from lipstream.engines.base import Engine
from tests.helpers import REPO


def test_packages_lint_clean() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "ruff", "check", "server", "client_sdk", "tests"],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stdout + result.stderr


def test_one_formatter_keeps_the_tree_formatted() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "ruff", "format", "--check", "server", "client_sdk", "tests"],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stdout + result.stderr


# Formatter exemptions: a table reads well as text parsed once (lipstream.tables).
EXEMPTION_DIRS = ("server", "client_sdk", "tests", "bench", "examples", "docker")
FORMATTER_EXEMPTION = re.compile(r"#\s*fmt:\s*(skip|off)\b")
# More parameters than this want a settings object; docs/explanation/architecture.md.
MAX_PARAMETERS = 12
SIGNATURE_DIRS = ("server", "client_sdk")


def formatter_exemptions(source: str) -> list[int]:
    """Lines of ``source`` with a ``# fmt: skip`` or ``# fmt: off`` comment (strings that
    spell one are not comments)."""
    if "fmt:" not in source:
        return []
    tokens = tokenize.generate_tokens(io.StringIO(source).readline)
    return [
        token.start[0]
        for token in tokens
        if token.type == tokenize.COMMENT and FORMATTER_EXEMPTION.search(token.string)
    ]


def _parameters(function: ast.FunctionDef | ast.AsyncFunctionDef) -> list[ast.arg]:
    arguments = function.args
    positional = [*arguments.posonlyargs, *arguments.args]
    if positional and positional[0].arg in ("self", "cls"):
        positional = positional[1:]
    rest = [a for a in (arguments.vararg, arguments.kwarg) if a is not None]
    return [*positional, *arguments.kwonlyargs, *rest]


def _keyword_hyperparameters(function: ast.FunctionDef | ast.AsyncFunctionDef) -> bool:
    """Every parameter but self keyword-only with a default, scikit-learn style."""
    arguments = function.args
    return (
        not arguments.posonlyargs
        and [a.arg for a in arguments.args] == ["self"]
        and arguments.vararg is None
        and arguments.kwarg is None
        and all(default is not None for default in arguments.kw_defaults)
    )


def long_signatures(source: str, is_estimator: Callable[[str], bool]) -> list[str]:
    """Functions in ``source`` over ``MAX_PARAMETERS`` parameters (self and cls not counted)
    as ``"name (count)"``. Exempt: ``__init__`` of a top-level class ``is_estimator`` accepts
    (an ``Engine``) when its parameters are keyword hyperparameters with defaults."""
    found = []
    tree = ast.parse(source)
    classes = {
        id(function): node.name
        for node in tree.body
        if isinstance(node, ast.ClassDef)
        for function in node.body
    }
    for node in ast.walk(tree):
        if not isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            continue
        count = len(_parameters(node))
        if count <= MAX_PARAMETERS:
            continue
        owner = classes.get(id(node))
        if (
            node.name == "__init__"
            and owner is not None
            and is_estimator(owner)
            and _keyword_hyperparameters(node)
        ):
            continue
        found.append(f"{node.name} ({count})")
    return found


def _python_files(directories: tuple[str, ...]) -> list[Path]:
    return sorted(path for name in directories for path in (REPO / name).rglob("*.py"))


def _engine_classes(path: Path) -> Callable[[str], bool]:
    """Whether a top-level class of ``path`` is an ``Engine``, importing the module only
    when asked (an over-long constructor is rare)."""
    relative = path.relative_to(REPO)

    def is_engine(name: str) -> bool:
        if relative.parts[0] != "server":
            return False
        module = importlib.import_module(".".join(relative.with_suffix("").parts[1:]))
        candidate = getattr(module, name, None)
        return isinstance(candidate, type) and issubclass(candidate, Engine)

    return is_engine


def test_no_formatter_exemptions() -> None:
    found = {
        str(path.relative_to(REPO)): lines
        for path in _python_files(EXEMPTION_DIRS)
        if (lines := formatter_exemptions(path.read_text(encoding="utf-8")))
    }
    assert found == {}


def test_exemption_finder_reads_comments_not_strings() -> None:
    source = 'x = 1  # fmt: skip\ny = "# fmt: off"\n# fmt: off\nz = 2\n# fmt: on\n'
    assert formatter_exemptions(source) == [1, 3]


def test_no_function_over_twelve_parameters() -> None:
    found = {
        str(path.relative_to(REPO)): names
        for path in _python_files(SIGNATURE_DIRS)
        if (names := long_signatures(path.read_text(encoding="utf-8"), _engine_classes(path)))
    }
    assert found == {}


def _function(name: str, count: int, *, keyword: bool = False, defaults: bool = True) -> str:
    default = " = 0" if defaults else ""
    parameters = ", ".join(f"p{i}: int{default}" for i in range(count))
    star = "*, " if keyword else ""
    return f"def {name}(self, {star}{parameters}) -> None:\n    pass\n"


def _class(name: str, method: str) -> str:
    return f"class {name}:\n" + "".join(f"    {line}\n" for line in method.splitlines())


def test_signature_checker_counts_parameters() -> None:
    assert long_signatures(_function("f", 12), lambda name: False) == []
    assert long_signatures(_function("f", 13), lambda name: False) == ["f (13)"]
    assert long_signatures("def g(*a: int, **k: int) -> None: ...", lambda name: False) == []
    nested = _class("C", _function("method", 13))
    assert long_signatures(nested, lambda name: False) == ["method (13)"]


def test_signature_checker_exempts_only_keyword_estimator_constructors() -> None:
    def estimator(name: str) -> bool:
        return name == "Estimator"

    keyword = _function("__init__", 17, keyword=True)
    assert long_signatures(_class("Estimator", keyword), estimator) == []
    assert long_signatures(_class("Other", keyword), estimator) == ["__init__ (17)"]
    positional = _function("__init__", 17)
    assert long_signatures(_class("Estimator", positional), estimator) == ["__init__ (17)"]
    required = _function("__init__", 13, keyword=True, defaults=False)
    assert long_signatures(_class("Estimator", required), estimator) == ["__init__ (13)"]
    method = _function("fit", 13, keyword=True)
    assert long_signatures(_class("Estimator", method), estimator) == ["fit (13)"]
