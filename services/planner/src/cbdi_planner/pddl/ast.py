"""Abstract syntax of lifted PDDL 2.1: what the parser builds and the grounder reads.

Conditions and effects are kept flat: a conjunction becomes a tuple and every leaf
carries its time specifier (`start`, `all`, `end`, or `inst` for instantaneous
actions, goals and preconditions), so later stages never re-walk nested `and`s.
"""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = [
    "Action",
    "Atom",
    "BinOp",
    "Compare",
    "Cond",
    "Domain",
    "DurationVar",
    "Effect",
    "ExistsCond",
    "Expr",
    "FHead",
    "ForallCond",
    "ForallEffect",
    "Lit",
    "Num",
    "NumEffect",
    "OrCond",
    "Param",
    "Problem",
    "TimedLiteral",
    "WhenEffect",
]

START, ALL, END, INST = "start", "all", "end", "inst"


@dataclass(frozen=True, slots=True)
class Atom:
    """A predicate applied to terms; a term starting with '?' is a variable."""

    predicate: str
    args: tuple[str, ...]

    def __str__(self) -> str:
        return f"({' '.join((self.predicate, *self.args))})"


@dataclass(frozen=True, slots=True)
class Param:
    """A typed variable; several types mean `(either ...)`."""

    name: str
    types: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class Num:
    """A numeric constant."""

    value: float


@dataclass(frozen=True, slots=True)
class FHead:
    """A function term such as `(loaded_amount ?a)`."""

    name: str
    args: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class DurationVar:
    """The `?duration` of the enclosing durative action."""


@dataclass(frozen=True, slots=True)
class BinOp:
    """An arithmetic operation `+ - * /` on two expressions."""

    op: str
    lhs: Expr
    rhs: Expr


Expr = Num | FHead | DurationVar | BinOp


@dataclass(frozen=True, slots=True)
class Lit:
    """A literal that must hold at `time`; predicate '=' is equality of two terms."""

    atom: Atom
    positive: bool
    time: str


@dataclass(frozen=True, slots=True)
class Compare:
    """A numeric comparison `< <= = >= >` that must hold at `time`."""

    op: str
    lhs: Expr
    rhs: Expr
    time: str


@dataclass(frozen=True, slots=True)
class ForallCond:
    """A universally quantified condition, expanded over the objects when grounding."""

    params: tuple[Param, ...]
    body: tuple[Cond, ...]


@dataclass(frozen=True, slots=True)
class ExistsCond:
    """An existentially quantified condition, a disjunction over the objects when grounding.

    `line`/`column` locate it, for the error when its disjunctive form grows too large.
    """

    params: tuple[Param, ...]
    body: tuple[Cond, ...]
    line: int = 0
    column: int = 0


@dataclass(frozen=True, slots=True)
class OrCond:
    """A disjunction of conjunctions; no part at all is the condition that never holds.

    The parser pushes negation down to literals and comparisons and reads `imply` as
    `or`, so this and `ExistsCond` are the only disjunctive nodes.
    """

    parts: tuple[tuple[Cond, ...], ...]
    line: int = 0
    column: int = 0


Cond = Lit | Compare | ForallCond | ExistsCond | OrCond


@dataclass(frozen=True, slots=True)
class TimedLiteral:
    """An add (positive) or delete effect at `time`."""

    atom: Atom
    positive: bool
    time: str


@dataclass(frozen=True, slots=True)
class NumEffect:
    """`increase`, `decrease`, `assign`, `scale-up` or `scale-down` of a function at `time`."""

    op: str
    head: FHead
    expr: Expr
    time: str


@dataclass(frozen=True, slots=True)
class ForallEffect:
    """A universally quantified effect."""

    params: tuple[Param, ...]
    body: tuple[Effect, ...]


@dataclass(frozen=True, slots=True)
class WhenEffect:
    """A conditional effect: `body` happens only where `condition` holds.

    In a durative action the condition may be at other times than the effect (a start
    condition guarding an end effect); `line`/`column` locate it for errors.
    """

    condition: tuple[Cond, ...]
    body: tuple[Effect, ...]
    line: int = 0
    column: int = 0


Effect = TimedLiteral | NumEffect | ForallEffect | WhenEffect


@dataclass(frozen=True, slots=True)
class Action:
    """A lifted action; `duration` is None for an instantaneous action.

    `duration` holds `(op, expr)` constraints on `?duration` with op in `= <= >=`.
    """

    name: str
    params: tuple[Param, ...]
    duration: tuple[tuple[str, Expr], ...] | None
    conditions: tuple[Cond, ...]
    effects: tuple[Effect, ...]
    line: int = 0
    column: int = 0

    @property
    def durative(self) -> bool:
        """Tell whether the action has a duration (start and end snap actions)."""
        return self.duration is not None


@dataclass(slots=True)
class Domain:
    """A parsed domain; `types` maps each type to its parents (PDDL allows several)."""

    name: str
    requirements: tuple[str, ...] = ()
    types: dict[str, tuple[str, ...]] = field(default_factory=dict)
    constants: dict[str, tuple[str, ...]] = field(default_factory=dict)
    predicates: dict[str, tuple[Param, ...]] = field(default_factory=dict)
    functions: dict[str, tuple[Param, ...]] = field(default_factory=dict)
    actions: list[Action] = field(default_factory=list)
    file: str = "<string>"


@dataclass(slots=True)
class Problem:
    """A parsed problem; timed initial literals are `(time, literal)` pairs."""

    name: str
    domain_name: str
    objects: dict[str, tuple[str, ...]] = field(default_factory=dict)
    init: list[Atom] = field(default_factory=list)
    init_numeric: dict[FHead, float] = field(default_factory=dict)
    timed_literals: list[tuple[float, TimedLiteral]] = field(default_factory=list)
    goal: tuple[Cond, ...] = ()
    metric: str | None = None
    file: str = "<string>"
