"""Read PDDL text into s-expressions that remember where they were written.

Every node carries its line and column so that later stages can point at the exact
place of a mistake.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from cbdi_planner.errors import PddlSyntaxError

__all__ = ["MAX_DEPTH", "SList", "SNode", "Sym", "read_sexpr"]

# Deeper lists are refused where they open: every later stage walks formulas
# recursively, and no real domain or problem comes near this.
MAX_DEPTH = 64
_TOKEN = re.compile(r"\s+|;[^\n]*|\(|\)|[^\s();]+")


@dataclass(frozen=True, slots=True)
class Sym:
    """A symbol (name, variable, keyword or number), lower-cased as PDDL is case-blind."""

    text: str
    line: int
    column: int


@dataclass(frozen=True, slots=True)
class SList:
    """A parenthesised list; `end_line`/`end_column` locate its closing parenthesis."""

    items: tuple[SNode, ...]
    line: int
    column: int
    end_line: int
    end_column: int


SNode = Sym | SList

# A list being read: the nodes read so far in it, and where its '(' is.
_Open = tuple[list[SNode], int, int]


def read_sexpr(text: str, file: str = "<string>") -> SList:
    """Read exactly one top-level list from `text`; reject unbalanced or trailing input,
    and lists nested deeper than MAX_DEPTH."""
    stack: list[_Open] = []
    result: SList | None = None
    line, line_start = 1, 0
    for match in _TOKEN.finditer(text):
        token = match.group()
        column = match.start() - line_start + 1
        if token[0].isspace() or token[0] == ";":
            newlines = token.count("\n")
            if newlines:
                line += newlines
                line_start = match.start() + token.rfind("\n") + 1
            continue
        if result is not None:
            raise PddlSyntaxError(
                f"unexpected {token!r} after the end of the definition",
                file=file,
                line=line,
                column=column,
                expected="end of file",
            )
        result = _take(token, stack, file, line, column)
    return _finish(result, stack, file, line, len(text) - line_start + 1)


def _take(token: str, stack: list[_Open], file: str, line: int, column: int) -> SList | None:
    """Add `token` to the lists open on `stack`; return the top-level list it closes, if one."""
    if token == "(":
        if len(stack) >= MAX_DEPTH:
            raise PddlSyntaxError(
                f"lists nested more than {MAX_DEPTH} deep",
                file=file,
                line=line,
                column=column,
                expected="a shallower expression",
            )
        stack.append(([], line, column))
    elif token == ")":
        if not stack:
            raise PddlSyntaxError(
                "unbalanced ')'", file=file, line=line, column=column, expected="'('"
            )
        items, open_line, open_column = stack.pop()
        node = SList(tuple(items), open_line, open_column, line, column)
        if not stack:
            return node
        stack[-1][0].append(node)
    elif not stack:
        raise PddlSyntaxError(
            f"unexpected {token!r} outside any list",
            file=file,
            line=line,
            column=column,
            expected="'('",
        )
    else:
        stack[-1][0].append(Sym(token.lower(), line, column))
    return None


def _finish(result: SList | None, stack: list[_Open], file: str, line: int, column: int) -> SList:
    """Return the definition read; refuse a list left open or a text with none.

    `line` and `column` are those of the end of the text.
    """
    if stack:
        _, open_line, open_column = stack[-1]
        raise PddlSyntaxError(
            f"the '(' at line {open_line}, column {open_column} is never closed",
            file=file,
            line=line,
            column=column,
            expected="')'",
        )
    if result is None:
        raise PddlSyntaxError(
            "no PDDL definition found",
            file=file,
            line=line,
            column=1,
            expected="'(define ...)'",
        )
    return result
