"""The house stays readable (issue 32): no module over 450 lines, no function over 60;
every test that sleeps for real is listed in docs/testing.md with its reason.

The core packages (`shared/src`, `services/*/src`) are what a newcomer reads first, and
the shipped domains (`domains/*/src`) what one copies for a domain of one's own; a
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
    roots += sorted((REPO / "domains").glob("*/src"))  # a domain is read as the core is
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


def _sleepers() -> set[tuple[str, tuple[str, ...]]]:
    """Return, for every real `time.sleep` or `asyncio.sleep` call in the tests (a duration
    other than a literal 0), its file under tests/ and the functions around it."""
    found = set()

    def walk(node: ast.AST, file: str, around: tuple[str, ...]) -> None:
        for child in ast.iter_child_nodes(node):
            inside = around
            if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef):
                inside = (*around, child.name)
            elif isinstance(child, ast.Call) and isinstance(child.func, ast.Attribute):
                func = child.func
                module = func.value.id if isinstance(func.value, ast.Name) else ""
                if func.attr == "sleep" and module in ("time", "asyncio"):
                    arg = child.args[0] if child.args else None
                    if not (isinstance(arg, ast.Constant) and arg.value == 0):
                        found.add((file, around))
            walk(child, file, inside)

    for path in sorted((REPO / "tests").rglob("*.py")):
        walk(ast.parse(path.read_text(), str(path)), str(path.relative_to(REPO / "tests")), ())
    return found


def test_every_test_that_sleeps_is_listed_with_its_reason() -> None:
    doc = (REPO / "docs" / "testing.md").read_text().splitlines()
    sleepers = _sleepers()
    assert ("conftest.py", ("router",)) in sleepers  # the walk finds them
    missing = sorted(
        f"{file}::{'.'.join(around)}"
        for file, around in sleepers
        if not any(
            f"`{file}`" in line and any(f"`{name}`" in line for name in around) for line in doc
        )
    )
    assert not missing, f"tests that sleep, not in docs/testing.md: {missing}"
