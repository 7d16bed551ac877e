"""Compile bound action instances into bitmask snap actions, with statics compiled away.

Static facts and static numeric functions are decided here, once: a condition on them
is either dropped (true) or removes its disjunct (false). What remains refers only to
facts and variables that can change. A condition with `or`, `imply` or `exists` is
turned into disjunctive normal form (dnf.py) and the instance into one ground action
per disjunct, all with the same name: a plan names the action, not the disjunct.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator

from cbdi_planner.dnf import Clause, Conj, TooManyDisjuncts, conjoin, disjoin
from cbdi_planner.effects import Body, Guard, build_snap, conditional
from cbdi_planner.errors import UnsupportedFeature
from cbdi_planner.pddl.ast import (
    ALL,
    END,
    INST,
    START,
    BinOp,
    Compare,
    Cond,
    DurationVar,
    Effect,
    ExistsCond,
    Expr,
    FHead,
    ForallCond,
    ForallEffect,
    Lit,
    Num,
    NumEffect,
    OrCond,
    Param,
    TimedLiteral,
    WhenEffect,
)
from cbdi_planner.reachability import GAtom, Instance, Objects
from cbdi_planner.task import (
    INTERNAL,
    CondEffect,
    GroundAction,
    NExpr,
    NumAssign,
    NumCond,
    eval_expr,
)

__all__ = ["Compiler", "Impossible"]

Env = dict[str, str]
_INSTANT = (None, 0, 0, (), (), None)  # no end, invariant or duration
_WORDS = {START: "at start", ALL: "over all", END: "at end", INST: "at once"}


class Impossible(Exception):
    """Raised when an expression needs a `?duration` that is not fixed."""


class Compiler:
    """Hold the fact and variable numbering while compiling instances."""

    def __init__(
        self,
        objects: Objects,
        static_atoms: set[GAtom],
        fluent_atoms: set[GAtom],
        init_numeric: dict[FHead, float],
        static_functions: set[str],
        file: str,
    ) -> None:
        self.objects = objects
        self.static_atoms = static_atoms
        self.fact_index: dict[GAtom, int] = {a: i for i, a in enumerate(sorted(fluent_atoms))}
        self.facts = ["(" + " ".join(a) + ")" for a in sorted(fluent_atoms)]
        self.init_numeric = {(h.name, *h.args): v for h, v in init_numeric.items()}
        self.static_functions = static_functions
        self.var_index: dict[tuple[str, ...], int] = {}
        self.file = file
        self.fluent_preds = {a[0] for a in fluent_atoms}

    def new_fact(self, name: str) -> int:
        """Add a fact of the planner's own (`name` starts with INTERNAL); return its bit."""
        self.fact_index[(name,)] = len(self.facts)
        self.facts.append(f"({name})")
        return 1 << (len(self.facts) - 1)

    def bindings(self, params: tuple[Param, ...], env: Env) -> Iterator[Env]:
        """Yield `env` extended by every typed assignment of `params`."""
        for values in itertools.product(*(self.objects.candidates(p) for p in params)):
            inner = dict(env)
            inner.update(zip((p.name for p in params), values, strict=True))
            yield inner

    # -- expressions ----------------------------------------------------------
    def expr(self, expr: Expr, env: Env, duration: float | None) -> NExpr:
        """Compile an expression, folding statics and a known ?duration into constants."""
        if isinstance(expr, Num):
            return ("c", expr.value)
        if isinstance(expr, DurationVar):
            if duration is None:
                raise Impossible("?duration") from None
            return ("c", duration)
        if isinstance(expr, FHead):
            key = (expr.name, *(env.get(a, a) for a in expr.args))
            if expr.name in self.static_functions:
                return ("c", self.init_numeric.get(key, math.nan))
            return ("v", self.var(key))
        assert isinstance(expr, BinOp)
        lhs, rhs = self.expr(expr.lhs, env, duration), self.expr(expr.rhs, env, duration)
        if lhs[0] == "c" and rhs[0] == "c":
            return ("c", eval_expr((expr.op, lhs, rhs), ()))
        return (expr.op, lhs, rhs)

    def var(self, key: tuple[str, ...]) -> int:
        """Return the index of a numeric variable, numbering it on first use."""
        if key not in self.var_index:
            self.var_index[key] = len(self.var_index)
        return self.var_index[key]

    # -- conditions -----------------------------------------------------------
    def condition(self, conds: tuple[Cond, ...], env: Env, duration: float | None) -> list[Clause]:
        """Return the disjuncts of a condition; [] when it can never hold.

        `forall` conjoins over the objects and `exists` disjoins over them. A disjunct
        with a false static literal disappears; a true static literal drops out.
        """
        base: Clause = {}
        parts: list[tuple[OrCond | ExistsCond, list[Clause]]] = []
        if not self._gather(conds, env, duration, base, parts):
            return []
        clauses = [] if any(c.pre & c.neg for c in base.values()) else [base]
        for cond, alternatives in parts:
            try:
                clauses = conjoin(clauses, alternatives)
            except TooManyDisjuncts as exc:
                exc.line, exc.column = exc.line or cond.line, exc.column or cond.column
                raise
        return clauses

    def _gather(
        self,
        conds: tuple[Cond, ...],
        env: Env,
        duration: float | None,
        base: Clause,
        parts: list[tuple[OrCond | ExistsCond, list[Clause]]],
    ) -> bool:
        """Add the plain literals of a conjunction to `base` (in place, the common case)
        and its disjunctions to `parts`; return False if it can never hold."""
        for cond in conds:
            if isinstance(cond, ForallCond):
                for inner in self.bindings(cond.params, env):
                    if not self._gather(cond.body, inner, duration, base, parts):
                        return False
            elif isinstance(cond, OrCond | ExistsCond):
                try:
                    alternatives = self._disjunction(cond, env, duration)
                except TooManyDisjuncts as exc:
                    exc.line, exc.column = exc.line or cond.line, exc.column or cond.column
                    raise
                if not alternatives:
                    return False
                parts.append((cond, alternatives))
            elif not self._leaf(cond, env, duration, base):
                return False
        return True

    def _disjunction(
        self, cond: OrCond | ExistsCond, env: Env, duration: float | None
    ) -> list[Clause]:
        if isinstance(cond, OrCond):
            return disjoin(self.condition(part, env, duration) for part in cond.parts)
        return disjoin(
            self.condition(cond.body, inner, duration) for inner in self.bindings(cond.params, env)
        )

    def _leaf(self, cond: Lit | Compare, env: Env, duration: float | None, base: Clause) -> bool:
        """Conjoin a literal or comparison to `base`; return False if it is false."""
        if isinstance(cond, Compare):
            check = NumCond(
                cond.op, self.expr(cond.lhs, env, duration), self.expr(cond.rhs, env, duration)
            )
            if check.lhs[0] == "c" and check.rhs[0] == "c":
                return check.holds(())
            base.setdefault(cond.time, Conj()).num.append(check)
            return True
        atom = (cond.atom.predicate, *(env.get(a, a) for a in cond.atom.args))
        if atom[0] == "=":
            return (atom[1] == atom[2]) == cond.positive
        if atom[0] not in self.fluent_preds:
            return (atom in self.static_atoms) == cond.positive
        index = self.fact_index.get(atom)
        if index is None:  # never reachable: never true
            return not cond.positive
        conj = base.setdefault(cond.time, Conj())
        if cond.positive:
            conj.pre |= 1 << index
        else:
            conj.neg |= 1 << index
        return True

    # -- effects --------------------------------------------------------------
    def effects(
        self, effects: tuple[Effect, ...], env: Env, out: Body, duration: float | None
    ) -> None:
        """Add effects to `out` by time."""
        for effect in effects:
            if isinstance(effect, ForallEffect):
                for inner in self.bindings(effect.params, env):
                    self.effects(effect.body, inner, out, duration)
            elif isinstance(effect, WhenEffect):
                self._when(effect, env, out, duration)
            elif isinstance(effect, NumEffect):
                key = (effect.head.name, *(env.get(a, a) for a in effect.head.args))
                assign = NumAssign(effect.op, self.var(key), self.expr(effect.expr, env, duration))
                out.slot(effect.time).num.append(assign)
            else:
                self._add_del(effect, env, out)

    def _add_del(self, effect: TimedLiteral, env: Env, out: Body) -> None:
        atom = (effect.atom.predicate, *(env.get(a, a) for a in effect.atom.args))
        index = self.fact_index.get(atom)
        if index is None:
            return  # deleting an atom that is never true changes nothing
        if effect.positive:
            out.slot(effect.time).add |= 1 << index
        else:
            out.slot(effect.time).dele |= 1 << index

    def _when(self, effect: WhenEffect, env: Env, out: Body, duration: float | None) -> None:
        """Add a conditional effect: at its own time, or as a guard (start condition,
        end effect)."""
        try:
            clauses = self.condition(effect.condition, env, duration)
        except TooManyDisjuncts as exc:
            if not exc.line:
                exc.line, exc.column = effect.line, effect.column
            raise
        if not clauses:
            return
        body = Body()
        self.effects(effect.body, env, body, duration)
        if body.guards:
            raise UnsupportedFeature(
                "a conditional effect with an at-start condition inside another one",
                file=self.file,
                line=effect.line,
                column=effect.column,
            )
        times = {t for clause in clauses for t, conj in clause.items() if not conj.empty()}
        for time, effs in body.times.items():
            if times <= {time}:
                out.slot(time).cond.extend(conditional(clauses, time, effs))
            elif time == END and times <= {START, END}:
                out.guards.append(Guard(clauses, effs))
            else:
                other = " and ".join(_WORDS[t] for t in sorted(times - {time}))
                raise UnsupportedFeature(
                    f"a conditional effect {_WORDS[time]} whose condition is checked {other} "
                    "(across times only a condition at start, or at start and at end, "
                    "on an effect at end is supported)",
                    file=self.file,
                    line=effect.line,
                    column=effect.column,
                )

    # -- actions --------------------------------------------------------------
    def actions(self, inst: Instance, index: int) -> list[GroundAction]:
        """Compile an instance into ground actions numbered from `index`, one per disjunct
        of its condition; [] when no disjunct can hold.

        A durative action split in several keeps one copy running at a time, through a
        fact of its own, as a single ground action does.
        """
        action = inst.action
        env = inst.binding()
        name = " ".join((action.name, *inst.args))
        durations, fixed = self._duration(inst, env)
        body = Body()
        variants = self._variants_of(inst, env, fixed, body)
        if action.duration is None:
            effs = body.at(INST)
            return [
                GroundAction(index + k, name, build_snap(c.get(INST), effs, None), *_INSTANT)
                for k, (c, _) in enumerate(variants)
            ]
        running = self.new_fact(f"{INTERNAL}running {name}") if len(variants) > 1 else 0
        out = []
        for k, (clause, guarded) in enumerate(variants):
            inv = clause.get(ALL, Conj())
            start, start_effs, end_effs = (
                clause.get(START),
                body.times.get(START),
                body.times.get(END),
            )
            if running:
                start = (start or Conj()).merged(Conj(neg=running))
                start_effs = body.at(START).extended(add=running)
            if running or guarded:
                end_effs = body.at(END).extended(dele=running, cond=guarded)
            out.append(
                GroundAction(
                    index + k,
                    name,
                    build_snap(start, start_effs, inv),
                    build_snap(clause.get(END), end_effs, inv),
                    inv.pre,
                    inv.neg,
                    tuple(inv.num),
                    durations,
                    fixed,
                )
            )
        return out

    def _variants_of(
        self, inst: Instance, env: Env, fixed: float | None, body: Body
    ) -> list[tuple[Clause, tuple[CondEffect, ...]]]:
        """Compile an instance's condition (its disjuncts) and effects into `body`;
        return `_variants` of them. An effect reading a duration that is not fixed, or
        a condition of too many disjuncts, is an error naming the action."""
        action = inst.action
        try:
            clauses = self.condition(action.conditions, env, fixed)
            if clauses:
                self.effects(action.effects, env, body, fixed)
            return _variants(clauses, body.guards)
        except Impossible:
            raise UnsupportedFeature(
                f"?duration in an effect of {action.name} whose duration is not fixed",
                file=self.file,
                line=action.line,
                column=action.column,
            ) from None
        except TooManyDisjuncts as exc:
            raise self.too_many(
                exc, f"the condition of {action.name}", action.line, action.column, self.file
            ) from None

    def goal(self, conds: tuple[Cond, ...], file: str) -> list[Conj]:
        """Return the disjuncts of a goal; [] when it can never hold."""
        try:
            clauses = self.condition(conds, {}, None)
        except TooManyDisjuncts as exc:
            raise self.too_many(exc, "the goal", 0, 0, file) from None
        return [clause.get(INST, Conj()) for clause in clauses]

    @staticmethod
    def too_many(
        exc: TooManyDisjuncts, what: str, line: int, column: int, file: str
    ) -> UnsupportedFeature:
        """Build the error for a disjunctive normal form past its limit, located at the
        innermost disjunction it grew in, else at `line`/`column`."""
        if exc.line:
            line, column = exc.line, exc.column
        return UnsupportedFeature(
            f"{what} has {exc.count} disjuncts in disjunctive normal form, more than "
            f"the {exc.limit} this planner grounds",
            file=file,
            line=line,
            column=column,
        )

    def _duration(
        self, inst: Instance, env: Env
    ) -> tuple[tuple[tuple[str, NExpr], ...], float | None]:
        if inst.action.duration is None:
            return (), None
        out = tuple((op, self.expr(e, env, None)) for op, e in inst.action.duration)
        fixed = next((float(e[1]) for op, e in out if op == "=" and e[0] == "c"), None)
        return out, fixed


def _variants(
    clauses: list[Clause], guards: list[Guard]
) -> list[tuple[Clause, tuple[CondEffect, ...]]]:
    """Split the condition's clauses further by each start-guarded conditional effect.

    Each guard's distinct start conditions are either required or forbidden at start
    (one copy per truth assignment), so the end snap knows which of them held.
    """
    variants: list[tuple[Clause, tuple[CondEffect, ...]]] = [(c, ()) for c in clauses]
    for guard in guards:
        outcomes = guard.outcomes()
        variants = [
            (merged, (*effects, *more))
            for clause, effects in variants
            for cond, more in outcomes
            for merged in conjoin([clause], cond)
        ]
        if len(variants) > TooManyDisjuncts.limit:
            raise TooManyDisjuncts(len(variants))
    return variants
