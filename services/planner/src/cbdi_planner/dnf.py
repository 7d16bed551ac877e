"""Disjunctive normal form over ground literals: the clauses under which a condition holds.

A `Clause` is a conjunction split by time (`start`, `all`, `end` or `inst`), each part
a `Conj` of fact bits and numeric comparisons. A condition is a list of clauses, its
disjuncts: `[]` never holds, `[{}]` always does. The search only ever sees one
conjunction per snap action, so a disjunctive precondition becomes one ground action
per clause (see compile.py); this module only does the Boolean algebra, and caps it:
past `MAX_DISJUNCTS` clauses it gives up rather than ground thousands of copies.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

from cbdi_planner.task import NumCond

__all__ = [
    "MAX_DISJUNCTS",
    "Clause",
    "Conj",
    "TooManyDisjuncts",
    "conjoin",
    "disjoin",
    "exclusive",
    "negate",
]

MAX_DISJUNCTS = 64

_NEGATED = {"<": (">=",), "<=": (">",), ">=": ("<",), ">": ("<=",), "=": ("<", ">")}


@dataclass(slots=True)
class Conj:
    """A conjunction: `pre` facts true, `neg` facts false, `num` comparisons true."""

    pre: int = 0
    neg: int = 0
    num: list[NumCond] = field(default_factory=list)

    def merged(self, other: Conj) -> Conj:
        """Return the conjunction of both (a new value)."""
        num = self.num + [c for c in other.num if c not in self.num]
        return Conj(self.pre | other.pre, self.neg | other.neg, num)

    def empty(self) -> bool:
        """Tell whether the conjunction is trivially true."""
        return not (self.pre or self.neg or self.num)

    def weaker(self, other: Conj) -> bool:
        """Tell whether every literal of `self` is one of `other` (so `other` implies it)."""
        return (
            self.pre & ~other.pre == 0
            and self.neg & ~other.neg == 0
            and all(c in other.num for c in self.num)
        )


Clause = dict[str, Conj]


class TooManyDisjuncts(Exception):
    """Raised when a disjunctive normal form would exceed `MAX_DISJUNCTS` clauses.

    `line`/`column` locate the innermost `or`/`exists`/`when` it grew in (0: unknown);
    the compiler turns this into an `UnsupportedFeature` naming the file.
    """

    limit = MAX_DISJUNCTS

    def __init__(self, count: int) -> None:
        self.count = count
        self.line = 0
        self.column = 0
        super().__init__(f"{count} disjuncts")


def _merge(a: Clause, b: Clause) -> Clause | None:
    """Conjoin two clauses; None when they contradict (a fact both true and false)."""
    out = dict(a)
    for time, conj in b.items():
        mine = out.get(time)
        both = conj if mine is None else mine.merged(conj)
        if both.pre & both.neg:
            return None
        out[time] = both
    return out


def _weaker(a: Clause, b: Clause) -> bool:
    return all(time in b and conj.weaker(b[time]) for time, conj in a.items() if not conj.empty())


def _size(clause: Clause) -> int:
    return sum(c.pre.bit_count() + c.neg.bit_count() + len(c.num) for c in clause.values())


def _simplify(clauses: list[Clause]) -> list[Clause]:
    """Drop contradictory clauses and those another clause implies (absorption)."""
    kept: list[Clause] = []
    for clause in sorted(clauses, key=_size):
        if any(c.pre & c.neg for c in clause.values()):
            continue
        if not any(_weaker(k, clause) for k in kept):
            kept.append(clause)
    return kept


def _capped(clauses: list[Clause]) -> list[Clause]:
    if len(clauses) > MAX_DISJUNCTS:
        raise TooManyDisjuncts(len(clauses))
    return clauses


def conjoin(left: list[Clause], right: list[Clause]) -> list[Clause]:
    """Return the DNF of `left and right` (the cross product of their clauses)."""
    if len(left) == 1 and len(right) == 1:
        merged = _merge(left[0], right[0])
        return [] if merged is None else [merged]
    if len(left) * len(right) > MAX_DISJUNCTS * MAX_DISJUNCTS:
        raise TooManyDisjuncts(len(left) * len(right))
    out = [m for a in left for b in right if (m := _merge(a, b)) is not None]
    return _capped(_simplify(out))


def disjoin(parts: Iterable[list[Clause]]) -> list[Clause]:
    """Return the DNF of the disjunction of `parts`."""
    out = [clause for part in parts for clause in part]
    if len(out) > MAX_DISJUNCTS * MAX_DISJUNCTS:
        raise TooManyDisjuncts(len(out))
    return _capped(_simplify(out))


def _literals(clause: Clause) -> list[Clause]:
    """Split a clause into one-literal clauses, in a fixed order."""
    out: list[Clause] = []
    for time in sorted(clause):
        conj = clause[time]
        for mask, positive in ((conj.pre, True), (conj.neg, False)):
            while mask:
                bit = mask & -mask
                mask ^= bit
                out.append({time: Conj(pre=bit) if positive else Conj(neg=bit)})
        out.extend({time: Conj(num=[check])} for check in conj.num)
    return out


def _negated_literal(literal: Clause) -> list[Clause]:
    ((time, conj),) = literal.items()
    if conj.pre:
        return [{time: Conj(neg=conj.pre)}]
    if conj.neg:
        return [{time: Conj(pre=conj.neg)}]
    check = conj.num[0]
    return [{time: Conj(num=[NumCond(op, check.lhs, check.rhs)])} for op in _NEGATED[check.op]]


def negate(clause: Clause) -> list[Clause]:
    """Return the DNF of `not clause`, its clauses mutually exclusive.

    `not (a and b and c)` is `not a`, `a and not b`, `a and b and not c`: at most one
    holds in any state, which `exclusive` relies on.
    """
    out: list[Clause] = []
    prefix: Clause = {}
    for literal in _literals(clause):
        for negated in _negated_literal(literal):
            merged = _merge(prefix, negated)
            if merged is not None:
                out.append(merged)
        prefix = _merge(prefix, literal) or {}
    return _capped(out)


def exclusive(clauses: list[Clause]) -> list[Clause]:
    """Return an equivalent DNF whose clauses never hold together: c1, c2 and not c1, ...

    A conditional effect that changes a number must fire once even where several
    disjuncts of its condition hold.
    """
    out: list[Clause] = []
    for k, clause in enumerate(clauses):
        pieces = [clause]
        for earlier in clauses[:k]:
            pieces = conjoin(pieces, negate(earlier))
        out.extend(pieces)
    return _capped(out)
