"""Ground effects on their way to snap actions: by time, conditional, start-guarded.

A conditional effect whose condition is a disjunction must still happen once: adds and
deletes may be listed once per disjunct (adding a fact twice adds it once), but a
numeric change gets mutually exclusive disjuncts. A durative action's `when` with an
at-start condition and an at-end effect is a `Guard`: the action is split by which of
its start conditions held, so the end snap knows without remembering anything.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

from cbdi_planner.dnf import (
    MAX_DISJUNCTS,
    Clause,
    Conj,
    TooManyDisjuncts,
    conjoin,
    disjoin,
    exclusive,
    negate,
)
from cbdi_planner.pddl.ast import END, START
from cbdi_planner.task import CondEffect, NumAssign, Snap, expr_vars

__all__ = ["Body", "Effs", "Guard", "build_snap", "conditional"]


@dataclass(slots=True)
class Effs:
    """The effects of one snap action: unconditional ones and conditional ones."""

    add: int = 0
    dele: int = 0
    num: list[NumAssign] = field(default_factory=list)
    cond: list[CondEffect] = field(default_factory=list)

    def extended(self, add: int = 0, dele: int = 0, cond: tuple[CondEffect, ...] = ()) -> Effs:
        """Return a copy with more adds, deletes and conditional effects."""
        return Effs(self.add | add, self.dele | dele, list(self.num), [*self.cond, *cond])


@dataclass(slots=True)
class Guard:
    """A `when` of a durative action with a condition at start and an effect at end.

    `clauses` is its condition in DNF (each with a start part, an end part or both),
    `effs` the effect at end.
    """

    clauses: list[Clause]
    effs: Effs

    def outcomes(self) -> list[tuple[list[Clause], list[CondEffect]]]:
        """Return, per truth assignment of the distinct start parts, the start condition
        that assignment means and the end effects it leaves."""
        starts: list[Conj] = []
        for clause in self.clauses:
            part = clause.get(START)
            if part is not None and not part.empty() and part not in starts:
                starts.append(part)
        if 2 ** len(starts) > MAX_DISJUNCTS:
            raise TooManyDisjuncts(2 ** len(starts))
        out = []
        for truth in itertools.product((True, False), repeat=len(starts)):
            cond: list[Clause] = [{}]
            for part, held in zip(starts, truth, strict=True):
                cond = conjoin(cond, [{START: part}] if held else negate({START: part}))
            if not cond:
                continue
            ends: list[Clause] = [
                {END: clause.get(END, Conj())}
                for clause in self.clauses
                if (part := clause.get(START)) is None or part.empty() or truth[starts.index(part)]
            ]
            out.append((cond, conditional(disjoin([ends]), END, self.effs) if ends else []))
        return out


@dataclass(slots=True)
class Body:
    """An action's effects by time, and its start-guarded end effects."""

    times: dict[str, Effs] = field(default_factory=dict)
    guards: list[Guard] = field(default_factory=list)

    def at(self, time: str) -> Effs:
        """Return the effects at `time`, to read (empty when there are none)."""
        return self.times.get(time) or Effs()

    def slot(self, time: str) -> Effs:
        """Return the effects at `time`, to add to."""
        return self.times.setdefault(time, Effs())


def conditional(clauses: list[Clause], time: str, effs: Effs) -> list[CondEffect]:
    """Return `effs` as conditional effects under the disjunction `clauses` (at `time`).

    A clause that is always true yields a conditional effect with no condition, which
    `build_snap` folds into the unconditional ones.
    """
    one = len(clauses) == 1
    out = []
    if one and (effs.add or effs.dele or effs.num):
        out.append(_cond(clauses[0], time, effs.add, effs.dele, tuple(effs.num)))
    if not one and (effs.add or effs.dele):
        out += [_cond(c, time, effs.add, effs.dele, ()) for c in clauses]
    once: list[Clause] | None = clauses if one else None
    if not one and effs.num:
        once = exclusive(clauses)
        out += [_cond(c, time, 0, 0, tuple(effs.num)) for c in once]
    for inner in effs.cond:  # a `when` inside a `when`: both conditions
        outers = clauses
        if inner.num_eff:
            once = once if once is not None else exclusive(clauses)
            outers = once
        for clause in outers:
            outer = clause.get(time, Conj())
            pre, neg = outer.pre | inner.pre, outer.neg | inner.neg
            if not pre & neg:
                num = (*outer.num, *inner.num_pre)
                out.append(CondEffect(pre, neg, num, inner.add, inner.dele, inner.num_eff))
    return out


def _cond(clause: Clause, time: str, add: int, dele: int, num: tuple[NumAssign, ...]) -> CondEffect:
    conj = clause.get(time, Conj())
    return CondEffect(conj.pre, conj.neg, tuple(conj.num), add, dele, num)


def build_snap(conj: Conj | None, effs: Effs | None, inv: Conj | None) -> Snap:
    """Build a snap action; the invariant counts as read for partial-order lifting.

    Conditional effects whose condition is empty become unconditional.
    """
    conj = conj or Conj()
    effs = effs or Effs()
    inv = inv or Conj()
    add, dele, num_eff = effs.add, effs.dele, list(effs.num)
    cond = []
    for ce in effs.cond:
        if ce.pre or ce.neg or ce.num_pre:
            cond.append(ce)
        else:
            add, dele = add | ce.add, dele | ce.dele
            num_eff.extend(ce.num_eff)
    reads = conj.pre | conj.neg | inv.pre | inv.neg
    writes = add | dele
    num_reads = 0
    for check in (*conj.num, *inv.num):
        num_reads |= expr_vars(check.lhs) | expr_vars(check.rhs)
    num_writes = 0
    for assign in num_eff:
        num_reads |= expr_vars(assign.expr)
        num_writes |= 1 << assign.var
    for ce in cond:
        reads |= ce.pre | ce.neg
        writes |= ce.add | ce.dele
        for check in ce.num_pre:
            num_reads |= expr_vars(check.lhs) | expr_vars(check.rhs)
        for assign in ce.num_eff:
            num_reads |= expr_vars(assign.expr)
            num_writes |= 1 << assign.var
    return Snap(
        conj.pre,
        conj.neg,
        tuple(conj.num),
        add,
        dele,
        tuple(num_eff),
        tuple(cond),
        reads,
        writes,
        num_reads,
        num_writes,
    )
