"""Errors of the planner: one class per way planning can fail.

Callers tell the cases apart by type (and the CLI by exit code): bad input is the user's
to fix, an unsolvable problem is a fact about the problem, a timeout is a fact about
the budget.
"""

from __future__ import annotations

__all__ = [
    "PddlError",
    "PddlSyntaxError",
    "PlanInvalid",
    "PlannerError",
    "SearchTimeout",
    "SemanticError",
    "Unsolvable",
    "UnsupportedFeature",
]


class PlannerError(Exception):
    """Base class of every error the planner raises on purpose."""


class PddlError(PlannerError):
    """Report bad PDDL input at a place in a file.

    `line` and `column` are 1-based; `expected` says what the reader should have found.
    """

    kind = "error"

    def __init__(
        self,
        message: str,
        *,
        file: str = "<string>",
        line: int = 0,
        column: int = 0,
        expected: str | None = None,
    ) -> None:
        self.message = message
        self.file = file
        self.line = line
        self.column = column
        self.expected = expected
        super().__init__(str(self))

    def __str__(self) -> str:
        where = f"{self.file}:{self.line}:{self.column}"
        text = f"{where}: {self.kind}: {self.message}"
        if self.expected:
            text += f" (expected {self.expected})"
        return text


class PddlSyntaxError(PddlError):
    """Report text that is not well-formed PDDL (parentheses, keywords, structure)."""

    kind = "syntax error"


class SemanticError(PddlError):
    """Report well-formed PDDL that makes no sense (unknown type, predicate, arity)."""

    kind = "semantic error"


class UnsupportedFeature(PddlError):
    """Report valid PDDL that uses a feature this planner does not handle."""

    kind = "unsupported"


class Unsolvable(PlannerError):
    """Report that the search space was exhausted: no plan exists (for this planner)."""


class SearchTimeout(PlannerError):
    """Report that the budget (time or expansions) ran out before a plan was found."""


class PlanInvalid(PlannerError):
    """Report that a plan does not execute from a state or does not reach the goal."""
