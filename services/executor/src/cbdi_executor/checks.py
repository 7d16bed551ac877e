"""Evaluate the ground conditions carried by plan steps against the agent's beliefs."""

from __future__ import annotations

import operator
from collections.abc import Callable, Iterable

from cbdi.beliefs import BeliefSet
from cbdi.wire.agent import Check

__all__ = ["describe", "first_failing"]

_NUMERIC: dict[str, Callable[[float, float], bool]] = {
    "EQ": operator.eq,
    "NE": operator.ne,
    "LT": operator.lt,
    "LE": operator.le,
    "GT": operator.gt,
    "GE": operator.ge,
}


def describe(check: Check) -> str:
    """Write a check as PDDL: `(free c_1_1)`, `(not (free c_1_1))`, `(< (load r) 3)`."""
    atom = f"({' '.join(check.atom)})"
    if check.op == "T":
        return atom
    if check.op == "F":
        return f"(not {atom})"
    symbol = {"EQ": "=", "NE": "!=", "LT": "<", "LE": "<=", "GT": ">", "GE": ">="}[check.op]
    return f"({symbol} {atom} {check.value:g})"


def _holds(check: Check, beliefs: BeliefSet) -> bool:
    atom = tuple(check.atom)
    if check.op == "T":
        return atom in beliefs.facts
    if check.op == "F":
        return atom not in beliefs.facts
    value = beliefs.fluents.get(atom)
    compare = _NUMERIC.get(check.op)
    if compare is None:
        raise ValueError(f"unknown check operator {check.op!r}")
    return value is not None and compare(value, check.value)


def first_failing(checks: Iterable[Check], beliefs: BeliefSet) -> Check | None:
    """Return the first check that does not hold, or None if all hold."""
    for check in checks:
        if not _holds(check, beliefs):
            return check
    return None
