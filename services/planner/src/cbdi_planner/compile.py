"""Compile bound action instances into bitmask snap actions, with statics compiled away.

Static facts and static numeric functions are decided here, once: a condition on them
is either dropped (true) or kills the instance (false). What remains refers only to
facts and variables that can change.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

from cbdi_planner.errors import UnsupportedFeature
from cbdi_planner.pddl.ast import (
    END,
    INST,
    START,
    BinOp,
    Compare,
    Cond,
    DurationVar,
    Effect,
    Expr,
    FHead,
    ForallCond,
    ForallEffect,
    Lit,
    Num,
    NumEffect,
    TimedLiteral,
    WhenEffect,
)
from cbdi_planner.reachability import GAtom, Instance, Objects
from cbdi_planner.task import (
    CondEffect,
    GroundAction,
    NExpr,
    NumAssign,
    NumCond,
    Snap,
    eval_expr,
    expr_vars,
)

__all__ = ["Compiler", "Impossible"]

Env = dict[str, str]


class Impossible(Exception):
    """Raised inside compilation when a static condition is false."""


@dataclass(slots=True)
class _Conj:
    pre: int = 0
    neg: int = 0
    num: list[NumCond] = field(default_factory=list)


@dataclass(slots=True)
class _Effs:
    add: int = 0
    dele: int = 0
    num: list[NumAssign] = field(default_factory=list)
    cond: list[CondEffect] = field(default_factory=list)


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
            if key not in self.var_index:
                self.var_index[key] = len(self.var_index)
            return ("v", self.var_index[key])
        assert isinstance(expr, BinOp)
        lhs, rhs = self.expr(expr.lhs, env, duration), self.expr(expr.rhs, env, duration)
        if lhs[0] == "c" and rhs[0] == "c":
            return ("c", eval_expr((expr.op, lhs, rhs), ()))
        return (expr.op, lhs, rhs)

    # -- conditions -----------------------------------------------------------
    def conds(
        self, conds: tuple[Cond, ...], env: Env, out: dict[str, _Conj], duration: float | None
    ) -> None:
        """Add conditions to `out` by time; raise Impossible if a static one is false."""
        for cond in conds:
            if isinstance(cond, ForallCond):
                for values in itertools.product(*(self.objects.candidates(p) for p in cond.params)):
                    inner = dict(env)
                    inner.update(zip((p.name for p in cond.params), values, strict=True))
                    self.conds(cond.body, inner, out, duration)
            elif isinstance(cond, Compare):
                check = NumCond(
                    cond.op, self.expr(cond.lhs, env, duration), self.expr(cond.rhs, env, duration)
                )
                if check.lhs[0] == "c" and check.rhs[0] == "c":
                    if not check.holds(()):
                        raise Impossible(cond)
                else:
                    out.setdefault(cond.time, _Conj()).num.append(check)
            else:
                self._literal(cond, env, out.setdefault(cond.time, _Conj()))

    def _literal(self, lit: Lit, env: Env, conj: _Conj) -> None:
        atom = (lit.atom.predicate, *(env.get(a, a) for a in lit.atom.args))
        if atom[0] == "=":
            if (atom[1] == atom[2]) != lit.positive:
                raise Impossible(lit)
            return
        if atom[0] not in self.fluent_preds:
            if (atom in self.static_atoms) != lit.positive:
                raise Impossible(lit)
            return
        index = self.fact_index.get(atom)
        if index is None:
            if lit.positive:
                raise Impossible(lit)  # never reachable
            return
        if lit.positive:
            conj.pre |= 1 << index
        else:
            conj.neg |= 1 << index

    # -- effects --------------------------------------------------------------
    def effects(
        self, effects: tuple[Effect, ...], env: Env, out: dict[str, _Effs], duration: float | None
    ) -> None:
        """Add effects to `out` by time."""
        for effect in effects:
            if isinstance(effect, ForallEffect):
                for values in itertools.product(
                    *(self.objects.candidates(p) for p in effect.params)
                ):
                    inner = dict(env)
                    inner.update(zip((p.name for p in effect.params), values, strict=True))
                    self.effects(effect.body, inner, out, duration)
            elif isinstance(effect, WhenEffect):
                self._when(effect, env, out, duration)
            elif isinstance(effect, NumEffect):
                key = NumAssign(
                    effect.op, self._var(effect.head, env), self.expr(effect.expr, env, duration)
                )
                out.setdefault(effect.time, _Effs()).num.append(key)
            else:
                self._add_del(effect, env, out.setdefault(effect.time, _Effs()))

    def _var(self, head: FHead, env: Env) -> int:
        key = (head.name, *(env.get(a, a) for a in head.args))
        if key not in self.var_index:
            self.var_index[key] = len(self.var_index)
        return self.var_index[key]

    def _add_del(self, effect: TimedLiteral, env: Env, effs: _Effs) -> None:
        atom = (effect.atom.predicate, *(env.get(a, a) for a in effect.atom.args))
        index = self.fact_index.get(atom)
        if index is None:
            return  # deleting an atom that is never true changes nothing
        if effect.positive:
            effs.add |= 1 << index
        else:
            effs.dele |= 1 << index

    def _when(
        self, effect: WhenEffect, env: Env, out: dict[str, _Effs], duration: float | None
    ) -> None:
        conds: dict[str, _Conj] = {}
        try:
            self.conds(effect.condition, env, conds, duration)
        except Impossible:
            return
        body: dict[str, _Effs] = {}
        self.effects(effect.body, env, body, duration)
        for time, effs in body.items():
            if any(t != time for t in conds):
                raise UnsupportedFeature(
                    "a conditional effect whose condition and effect are at different times",
                    file=self.file,
                )
            conj = conds.get(time, _Conj())
            target = out.setdefault(time, _Effs())
            if not (conj.pre or conj.neg or conj.num):
                target.add |= effs.add
                target.dele |= effs.dele
                target.num.extend(effs.num)
            else:
                target.cond.append(
                    CondEffect(
                        conj.pre, conj.neg, tuple(conj.num), effs.add, effs.dele, tuple(effs.num)
                    )
                )

    # -- actions --------------------------------------------------------------
    def action(self, inst: Instance, index: int) -> GroundAction | None:
        """Compile an instance; return None when a static condition rules it out."""
        env = inst.binding()
        name = " ".join((inst.action.name, *inst.args))
        durations, fixed = self._duration(inst, env)
        conds: dict[str, _Conj] = {}
        effs: dict[str, _Effs] = {}
        try:
            self.conds(inst.action.conditions, env, conds, fixed)
            self.effects(inst.action.effects, env, effs, fixed)
        except Impossible as exc:
            if exc.args == ("?duration",):
                raise UnsupportedFeature(
                    f"?duration in an effect of {inst.action.name} whose duration is not fixed",
                    file=self.file,
                    line=inst.action.line,
                    column=inst.action.column,
                ) from None
            return None
        if inst.action.duration is None:
            return GroundAction(
                index, name, _snap(conds.get(INST), effs.get(INST), None), None, 0, 0, (), (), None
            )
        inv = conds.get("all", _Conj())
        return GroundAction(
            index,
            name,
            _snap(conds.get(START), effs.get(START), inv),
            _snap(conds.get(END), effs.get(END), inv),
            inv.pre,
            inv.neg,
            tuple(inv.num),
            durations,
            fixed,
        )

    def _duration(
        self, inst: Instance, env: Env
    ) -> tuple[tuple[tuple[str, NExpr], ...], float | None]:
        if inst.action.duration is None:
            return (), None
        out = tuple((op, self.expr(e, env, None)) for op, e in inst.action.duration)
        fixed = next((float(e[1]) for op, e in out if op == "=" and e[0] == "c"), None)
        return out, fixed


def _snap(conj: _Conj | None, effs: _Effs | None, inv: _Conj | None) -> Snap:
    """Build a snap action; the invariant counts as read for partial-order lifting."""
    conj = conj or _Conj()
    effs = effs or _Effs()
    inv = inv or _Conj()
    reads = conj.pre | conj.neg | inv.pre | inv.neg
    writes = effs.add | effs.dele
    num_reads = 0
    for check in (*conj.num, *inv.num):
        num_reads |= expr_vars(check.lhs) | expr_vars(check.rhs)
    num_writes = 0
    for assign in effs.num:
        num_reads |= expr_vars(assign.expr)
        num_writes |= 1 << assign.var
    for ce in effs.cond:
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
        effs.add,
        effs.dele,
        tuple(effs.num),
        tuple(effs.cond),
        reads,
        writes,
        num_reads,
        num_writes,
    )
