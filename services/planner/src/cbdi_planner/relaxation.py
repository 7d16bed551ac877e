"""The relaxation the heuristic evaluates: snap actions as relaxed operators, numeric
conditions as intervals that effects can only widen (`heuristic.RelaxedPlanGraph`).

Each durative action becomes two relaxed operators: its start (adding the start
effects and a `pending` token) and its end (needing the token, the end condition and
the invariant); deletes are ignored.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from cbdi_planner.stn import END, INST, START, TIL
from cbdi_planner.task import GroundAction, NExpr, NumAssign, NumCond, Task
from cbdi_planner.task import bit_positions as _bits

__all__ = ["RelaxedOp", "may_hold", "relaxed_ops", "widen"]


@dataclass(frozen=True, slots=True)
class RelaxedOp:
    """One relaxed operator: an action's start, end or the whole of it (compressed), an
    instant action, or a timed literal; what it needs and adds, as fact indices."""

    kind: int
    action: int
    pre: tuple[int, ...]
    add: tuple[int, ...]
    num_pre: tuple[NumCond, ...]
    num_eff: tuple[NumAssign, ...]


def interval(expr: NExpr, lo: list[float], hi: list[float]) -> tuple[float, float]:
    """Return the interval `expr` may take when each variable lies in [lo, hi]."""
    tag = expr[0]
    if tag == "c":
        return float(expr[1]), float(expr[1])
    if tag == "v":
        return lo[expr[1]], hi[expr[1]]
    (a, b), (c, d) = interval(expr[1], lo, hi), interval(expr[2], lo, hi)
    if tag == "+":
        return a + c, b + d
    if tag == "-":
        return a - d, b - c
    if tag == "*":
        products = [
            x * y for x in (a, b) for y in (c, d) if not (math.isinf(x) or math.isinf(y))
        ] or [-math.inf, math.inf]
        has_inf = any(math.isinf(v) for v in (a, b, c, d))
        return (-math.inf, math.inf) if has_inf else (min(products), max(products))
    return -math.inf, math.inf


def may_hold(cond: NumCond, lo: list[float], hi: list[float]) -> bool:
    """Tell whether `cond` may hold for some values within the intervals."""
    (a, b), (c, d) = interval(cond.lhs, lo, hi), interval(cond.rhs, lo, hi)
    if any(math.isnan(v) for v in (a, b, c, d)):
        return False
    if cond.op in ("<", "<="):
        return a < d or (cond.op == "<=" and a <= d)
    if cond.op in (">", ">="):
        return b > c or (cond.op == ">=" and b >= c)
    return a <= d and c <= b


def widen(effect: NumAssign, lo: list[float], hi: list[float]) -> bool:
    """Widen the effect's variable by what `effect` may do to it; True if it grew."""
    a, b = interval(effect.expr, lo, hi)
    old = (lo[effect.var], hi[effect.var])
    if effect.op == "assign":
        lo[effect.var], hi[effect.var] = min(old[0], a), max(old[1], b)
    elif effect.op in ("increase", "decrease"):
        up, down = (b > 0, a < 0) if effect.op == "increase" else (a < 0, b > 0)
        if up:
            hi[effect.var] = math.inf
        if down:
            lo[effect.var] = -math.inf
    else:
        lo[effect.var], hi[effect.var] = -math.inf, math.inf
    return (lo[effect.var], hi[effect.var]) != old


def relaxed_ops(
    task: Task, compress: bool, pending: int, ended: int
) -> tuple[list[RelaxedOp], dict[int, int]]:
    """Return the relaxed operators of `task` and which end op each start op enables by
    itself (`then[k]`: its other conditions are the start's conditions or effects, so
    it fires one layer later without counters). `pending + a` and `ended + a` are the
    facts that action `a` runs and has ended; `compress`: one operator per action, as
    `RelaxedPlanGraph` explains.
    """
    ops: list[RelaxedOp] = []
    then: dict[int, int] = {}
    for a in task.actions:
        mine, chained = _action_ops(a, compress, pending, ended)
        if chained:
            then[len(ops)] = len(ops) + 1
        ops += mine
    for i, til in enumerate(task.tils):
        ops.append(RelaxedOp(TIL, i, (), _bits(til.add), (), ()))
    return ops, then


def _action_ops(
    a: GroundAction, compress: bool, pending: int, ended: int
) -> tuple[list[RelaxedOp], bool]:
    """Return the relaxed operators of action `a` (`relaxed_ops`), and whether its end op
    is chained to its start (enabled by the start alone)."""
    start = a.start
    cond_add = 0
    for ce in start.cond_effects:
        cond_add |= ce.add
    if a.end is None:
        return [
            RelaxedOp(
                INST,
                a.index,
                _bits(start.pre),
                _bits(start.add | cond_add),
                start.num_pre,
                start.num_eff,
            )
        ], False
    end_add = a.end.add
    for ce in a.end.cond_effects:
        end_add |= ce.add
    if compress:
        return [
            RelaxedOp(
                START,
                a.index,
                _bits(start.pre | ((a.inv | a.end.pre) & ~start.add)),
                _bits(start.add | cond_add | end_add),
                start.num_pre + a.end.num_pre + a.inv_num,
                start.num_eff + a.end.num_eff,
            )
        ], False
    pre = start.pre | (a.inv & ~start.add)
    chained = not (a.end.pre | a.inv) & ~(pre | start.add)
    return [
        RelaxedOp(
            START,
            a.index,
            _bits(pre),
            (*_bits(start.add | cond_add), pending + a.index),
            start.num_pre,
            start.num_eff,
        ),
        RelaxedOp(
            END,
            a.index,
            (*_bits(a.end.pre | a.inv), pending + a.index),
            (*_bits(end_add), ended + a.index),
            a.end.num_pre + a.inv_num,
            a.end.num_eff,
        ),
    ], chained
