"""The ground planning task: integer-indexed facts, numeric variables and snap actions.

Facts are bit positions in a Python int, so a set of facts is one int and checking a
precondition is `pre & ~facts == 0`. A durative action is two snap actions (start and
end) plus an invariant that must hold while it runs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

__all__ = [
    "INTERNAL",
    "CondEffect",
    "GroundAction",
    "NExpr",
    "NumAssign",
    "NumCond",
    "Snap",
    "Task",
    "TimedLiterals",
    "bit_positions",
    "eval_expr",
    "expr_vars",
    "holds",
]

# The facts and actions the planner adds itself start with this, which no PDDL name can.
INTERNAL = "#"

# A compiled numeric expression: ("c", value) | ("v", var) | (op, lhs, rhs).
NExpr = tuple[Any, ...]


def bit_positions(mask: int) -> tuple[int, ...]:
    """Return the positions of the set bits of `mask`, lowest first.

    Scanning the binary text is linear in the width; peeling off the lowest bit of a
    wide int costs a copy of the int per bit (a state of a 30x30 map has 650 of them).
    """
    text = format(mask, "b")[::-1]
    out = []
    i = text.find("1")
    while i >= 0:
        out.append(i)
        i = text.find("1", i + 1)
    return tuple(out)


def eval_expr(expr: NExpr, nums: tuple[float, ...]) -> float:
    """Evaluate a compiled expression; an undefined variable (nan) propagates."""
    tag = expr[0]
    if tag == "c":
        return float(expr[1])
    if tag == "v":
        return nums[expr[1]]
    lhs, rhs = eval_expr(expr[1], nums), eval_expr(expr[2], nums)
    if tag == "+":
        return lhs + rhs
    if tag == "-":
        return lhs - rhs
    if tag == "*":
        return lhs * rhs
    return lhs / rhs if rhs != 0 else math.nan


def expr_vars(expr: NExpr) -> int:
    """Return the bitmask of numeric variables an expression reads."""
    if expr[0] == "c":
        return 0
    if expr[0] == "v":
        return 1 << int(expr[1])
    return expr_vars(expr[1]) | expr_vars(expr[2])


@dataclass(frozen=True, slots=True)
class NumCond:
    """A numeric comparison `lhs op rhs`."""

    op: str
    lhs: NExpr
    rhs: NExpr

    def holds(self, nums: tuple[float, ...]) -> bool:
        """Tell whether the comparison is true (false on undefined values)."""
        a, b = eval_expr(self.lhs, nums), eval_expr(self.rhs, nums)
        op = self.op
        if op == "<":
            return a < b
        if op == "<=":
            return a <= b
        if op == "=":
            return abs(a - b) < 1e-9
        if op == ">=":
            return a >= b
        return a > b


@dataclass(frozen=True, slots=True)
class NumAssign:
    """An update of numeric variable `var` by `op` with the value of `expr`."""

    op: str
    var: int
    expr: NExpr

    def apply(self, old: tuple[float, ...], new: list[float]) -> None:
        """Write the effect into `new`, reading expressions in the old state `old`."""
        value = eval_expr(self.expr, old)
        if self.op == "assign":
            new[self.var] = value
        elif self.op == "increase":
            new[self.var] += value
        elif self.op == "decrease":
            new[self.var] -= value
        elif self.op == "scale-up":
            new[self.var] *= value
        else:
            new[self.var] = new[self.var] / value if value else math.nan


@dataclass(frozen=True, slots=True)
class CondEffect:
    """A conditional effect: applies when `pre` facts hold, `neg` facts do not."""

    pre: int
    neg: int
    num_pre: tuple[NumCond, ...]
    add: int
    dele: int
    num_eff: tuple[NumAssign, ...]


def holds(
    pre: int, neg: int, num_pre: tuple[NumCond, ...], facts: int, nums: tuple[float, ...]
) -> bool:
    """Tell whether a conjunction of literals and comparisons holds in a state."""
    return (pre & ~facts) == 0 and (neg & facts) == 0 and all(c.holds(nums) for c in num_pre)


@dataclass(frozen=True, slots=True)
class Snap:
    """A happening: the start or end of a durative action, or an instantaneous action.

    `reads`/`writes` (facts) and `num_reads`/`num_writes` (variables) decide which
    earlier steps a step must follow when the plan is lifted to a partial order.
    """

    pre: int
    neg: int
    num_pre: tuple[NumCond, ...]
    add: int
    dele: int
    num_eff: tuple[NumAssign, ...]
    cond_effects: tuple[CondEffect, ...]
    reads: int
    writes: int
    num_reads: int
    num_writes: int

    def apply(self, facts: int, nums: tuple[float, ...]) -> tuple[int, tuple[float, ...]]:
        """Return the state after this happening (deletes before adds, as PDDL says)."""
        add, dele, num_eff = self.add, self.dele, self.num_eff
        if self.cond_effects:
            extra: list[NumAssign] = []
            for ce in self.cond_effects:
                if holds(ce.pre, ce.neg, ce.num_pre, facts, nums):
                    add |= ce.add
                    dele |= ce.dele
                    extra.extend(ce.num_eff)
            num_eff = num_eff + tuple(extra)
        new_facts = (facts & ~dele) | add
        if not num_eff:
            return new_facts, nums
        values = list(nums)
        for effect in num_eff:
            effect.apply(nums, values)
        return new_facts, tuple(values)


@dataclass(frozen=True, slots=True)
class GroundAction:
    """A ground action; `end` is None for an instantaneous action.

    Several ground actions may share a name: one per disjunct of a disjunctive
    condition. A plan names the action, and any of them may be the one meant.

    The invariant (`inv`, `inv_neg`, `inv_num`) is the `over all` condition.
    `duration` holds `(op, expr)` constraints; `fixed_duration` is set when they pin a
    constant, which is the common case.
    """

    index: int
    name: str
    start: Snap
    end: Snap | None
    inv: int
    inv_neg: int
    inv_num: tuple[NumCond, ...]
    duration: tuple[tuple[str, NExpr], ...]
    fixed_duration: float | None

    @property
    def durative(self) -> bool:
        """Tell whether the action has a start and an end."""
        return self.end is not None

    @property
    def internal(self) -> bool:
        """Tell whether the planner added the action (it never appears in a plan)."""
        return self.name.startswith(INTERNAL)

    def duration_bounds(self, nums: tuple[float, ...], epsilon: float) -> tuple[float, float]:
        """Return the [min, max] duration allowed when starting in a state with `nums`."""
        if self.fixed_duration is not None:
            return self.fixed_duration, self.fixed_duration
        low, high = epsilon, math.inf
        for op, expr in self.duration:
            value = eval_expr(expr, nums)
            if op in ("=", ">="):
                low = max(low, value)
            if op in ("=", "<="):
                high = min(high, value)
        return low, high


@dataclass(frozen=True, slots=True)
class TimedLiterals:
    """The timed initial literals that happen at one time."""

    time: float
    add: int
    dele: int


@dataclass(slots=True)
class Task:
    """A ground task: everything the search needs, with names only for printing."""

    facts: list[str]
    num_vars: list[str]
    actions: list[GroundAction]
    init_facts: int
    init_nums: tuple[float, ...]
    goal: int
    goal_neg: int
    goal_num: tuple[NumCond, ...]
    tils: list[TimedLiterals]
    name: str = ""

    def fact_names(self, facts: int) -> list[str]:
        """Return the names of the facts set in a bitmask, for messages and tests."""
        out = []
        while facts:
            low = facts & -facts
            out.append(self.facts[low.bit_length() - 1])
            facts ^= low
        return out
