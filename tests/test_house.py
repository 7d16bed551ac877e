"""The house stays readable: no module over 450 lines, no function over 60 (issue 32).

The core packages (`shared/src`, `services/*/src`) are what a newcomer reads first; a
unit past these sizes is usually two concepts. A function counts from its `def` to its
last line, docstring included.
"""

from __future__ import annotations

import ast
from pathlib import Path

from tests_support import REPO

MODULE_LINES = 450
FUNCTION_LINES = 60


def _sources() -> list[Path]:
    roots = [REPO / "shared" / "src", *sorted((REPO / "services").glob("*/src"))]
    return sorted(p for root in roots for p in root.rglob("*.py"))


def test_the_core_is_searched() -> None:
    names = {p.name for p in _sources()}
    assert {"keys.py", "heuristic.py", "sexpr.py"} <= names


def test_no_module_is_over_450_lines() -> None:
    long = {}
    for path in _sources():
        lines = path.read_text().count("\n")
        if lines > MODULE_LINES:
            long[str(path.relative_to(REPO))] = lines
    assert not long, f"modules over {MODULE_LINES} lines: {long}"


def test_no_function_is_over_60_lines() -> None:
    long = {}
    for path in _sources():
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                assert node.end_lineno is not None
                lines = node.end_lineno - node.lineno + 1
                if lines > FUNCTION_LINES:
                    long[f"{path.relative_to(REPO)}:{node.lineno} {node.name}"] = lines
    assert not long, f"functions over {FUNCTION_LINES} lines: {long}"
