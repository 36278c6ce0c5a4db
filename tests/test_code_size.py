"""The project's size rules: every module under featurewarp_cli/ and warps/ is under 500 lines,
every function (methods and nested functions too, docstring included) under 80."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
MODULE_LINES = 500
FUNCTION_LINES = 80
MODULES = sorted(path.relative_to(ROOT).as_posix()
                 for folder in ("featurewarp_cli", "warps") for path in (ROOT / folder).rglob("*.py"))


def long_functions(source: str) -> list[str]:
    """``name (N lines)`` for each function of ``source`` with FUNCTION_LINES lines or more."""
    return [f"{node.name} ({node.end_lineno - node.lineno + 1} lines)" for node in ast.walk(ast.parse(source))
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
            and node.end_lineno - node.lineno + 1 >= FUNCTION_LINES]


def test_the_rules_see_every_module():
    assert "featurewarp_cli/cli/main.py" in MODULES and "warps/swirl.py" in MODULES


@pytest.mark.parametrize("module", MODULES)
def test_module_and_functions_are_small(module):
    source = (ROOT / module).read_text()
    lines = len(source.splitlines())
    problems = [f"{lines} lines"] if lines >= MODULE_LINES else []
    problems += long_functions(source)
    assert not problems, f"{module}: {', '.join(problems)}"


def test_long_functions_are_found():
    body = "".join(f"    x{i} = {i}\n" for i in range(FUNCTION_LINES))
    assert long_functions(f"class A:\n  def f(self):\n{body}\n") == [f"f ({FUNCTION_LINES + 1} lines)"]
    assert long_functions("def g():\n    return 1\n") == []
