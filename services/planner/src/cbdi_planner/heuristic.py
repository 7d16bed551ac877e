"""Temporal relaxed planning graph heuristic with helpful actions (FF over snap actions).

Each durative action becomes two relaxed operators: its start (adding the start
effects and a `pending` token) and its end (needing the token, the end condition and
the invariant). A running action starts with its token, and its `ended` token is a
goal, so the relaxed plan must finish what the state has started. Deletes are ignored;
numeric conditions are relaxed to intervals that effects can only widen. The graph is
built with precondition counters, so one evaluation costs time linear in the
relaxed-reachable part of the task, not in the number of layers times actions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from cbdi_planner.state import State
from cbdi_planner.stn import END, INST, START, TIL
from cbdi_planner.task import NExpr, NumAssign, NumCond, Task

__all__ = ["INFINITE", "Estimate", "RelaxedPlanGraph"]

INFINITE = 1 << 30


@dataclass(frozen=True, slots=True)
class Estimate:
    """A heuristic value and the helpful happenings `(kind, action)` of a state."""

    value: int
    helpful: frozenset[tuple[int, int]]


@dataclass(frozen=True, slots=True)
class _Op:
    kind: int
    action: int
    pre: tuple[int, ...]
    add: tuple[int, ...]
    num_pre: tuple[NumCond, ...]
    num_eff: tuple[NumAssign, ...]


def _bits(mask: int) -> tuple[int, ...]:
    out = []
    while mask:
        low = mask & -mask
        out.append(low.bit_length() - 1)
        mask ^= low
    return tuple(out)


def _interval(expr: NExpr, lo: list[float], hi: list[float]) -> tuple[float, float]:
    tag = expr[0]
    if tag == "c":
        return float(expr[1]), float(expr[1])
    if tag == "v":
        return lo[expr[1]], hi[expr[1]]
    (a, b), (c, d) = _interval(expr[1], lo, hi), _interval(expr[2], lo, hi)
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


def _may_hold(cond: NumCond, lo: list[float], hi: list[float]) -> bool:
    (a, b), (c, d) = _interval(cond.lhs, lo, hi), _interval(cond.rhs, lo, hi)
    if any(math.isnan(v) for v in (a, b, c, d)):
        return False
    if cond.op in ("<", "<="):
        return a < d or (cond.op == "<=" and a <= d)
    if cond.op in (">", ">="):
        return b > c or (cond.op == ">=" and b >= c)
    return a <= d and c <= b


def _widen(effect: NumAssign, lo: list[float], hi: list[float]) -> bool:
    a, b = _interval(effect.expr, lo, hi)
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


class RelaxedPlanGraph:
    """Precomputed relaxed operators of a task; `estimate` evaluates one state."""

    def __init__(self, task: Task) -> None:
        self.task = task
        n_facts, n_actions = len(task.facts), len(task.actions)
        self.pending = n_facts
        self.ended = n_facts + n_actions
        self.size = n_facts + 2 * n_actions + len(task.tils)
        self.ops: list[_Op] = []
        for a in task.actions:
            start = a.start
            cond_add = 0
            for ce in start.cond_effects:
                cond_add |= ce.add
            if a.end is None:
                self.ops.append(
                    _Op(
                        INST,
                        a.index,
                        _bits(start.pre),
                        _bits(start.add | cond_add),
                        start.num_pre,
                        start.num_eff,
                    )
                )
                continue
            pre = start.pre | (a.inv & ~start.add)
            self.ops.append(
                _Op(
                    START,
                    a.index,
                    _bits(pre),
                    (*_bits(start.add | cond_add), self.pending + a.index),
                    start.num_pre,
                    start.num_eff,
                )
            )
            end_add = a.end.add
            for ce in a.end.cond_effects:
                end_add |= ce.add
            self.ops.append(
                _Op(
                    END,
                    a.index,
                    (*_bits(a.end.pre | a.inv), self.pending + a.index),
                    (*_bits(end_add), self.ended + a.index),
                    a.end.num_pre + a.inv_num,
                    a.end.num_eff,
                )
            )
        for i, til in enumerate(task.tils):
            self.ops.append(_Op(TIL, i, (), _bits(til.add), (), ()))
        self.users: list[list[int]] = [[] for _ in range(self.size)]
        for k, op in enumerate(self.ops):
            for f in op.pre:
                self.users[f].append(k)
        self.counts = [len(op.pre) for op in self.ops]
        self.goal = _bits(task.goal)

    def estimate(self, state: State) -> Estimate:
        """Return the relaxed plan length and the helpful happenings of `state`."""
        level = [-1] * self.size
        achiever = [-1] * self.size
        counts = self.counts[:]
        frontier = list(_bits(state.facts))
        frontier += [self.pending + a for a in state.open]
        goals = list(self.goal) + [self.ended + a for a in state.open]
        for f in frontier:
            level[f] = 0
        lo = list(state.nums)
        hi = list(state.nums)
        ready = [
            k
            for k, op in enumerate(self.ops)
            if not op.pre and (op.kind != TIL or op.action >= state.til)
        ]
        waiting: list[int] = []
        missing = sum(1 for g in goals if level[g] < 0)
        op_level: dict[int, int] = {}
        depth = 0
        while missing:
            for f in frontier:
                for k in self.users[f]:
                    counts[k] -= 1
                    if counts[k] == 0:
                        ready.append(k)
            layer, waiting = self._layer(waiting + ready, op_level, lo, hi)
            ready = []
            if not layer:
                return Estimate(INFINITE, frozenset())
            frontier = []
            for k in layer:
                op_level[k] = depth
                op = self.ops[k]
                for f in op.add:
                    if level[f] < 0:
                        level[f] = depth + 1
                        achiever[f] = k
                        frontier.append(f)
                for effect in op.num_eff:
                    _widen(effect, lo, hi)
            missing = sum(1 for g in goals if level[g] < 0)
            depth += 1
        return self._extract(goals, level, achiever, op_level, state)

    def _layer(
        self, candidates: list[int], op_level: dict[int, int], lo: list[float], hi: list[float]
    ) -> tuple[list[int], list[int]]:
        """Split the ops whose facts are reached into this layer and those still waiting.

        An op waits while its numeric condition cannot hold yet; each op is taken once.
        """
        layer: list[int] = []
        waiting: list[int] = []
        for k in candidates:
            if k in op_level:
                continue
            op = self.ops[k]
            if op.num_pre and not all(_may_hold(c, lo, hi) for c in op.num_pre):
                waiting.append(k)
            else:
                layer.append(k)
        return layer, waiting

    def _extract(
        self,
        goals: list[int],
        level: list[int],
        achiever: list[int],
        op_level: dict[int, int],
        state: State,
    ) -> Estimate:
        """Extract a relaxed plan backwards (FF); helpful = applicable ops adding layer-1 goals."""
        top = max((level[g] for g in goals), default=0)
        buckets: list[set[int]] = [set() for _ in range(top + 1)]
        for g in goals:
            buckets[level[g]].add(g)
        chosen: set[int] = set()
        done: set[int] = set()
        for depth in range(top, 0, -1):
            for g in buckets[depth]:
                if g in done:
                    continue
                k = achiever[g]
                if k in chosen:
                    continue
                chosen.add(k)
                op = self.ops[k]
                done.update(op.add)
                for p in op.pre:
                    if level[p] > 0 and p not in done:
                        buckets[level[p]].add(p)
        first_goals = buckets[1] if top >= 1 else set()
        helpful = set()
        for k, depth in op_level.items():
            if depth == 0:
                op = self.ops[k]
                if op.kind == TIL and op.action != state.til:
                    continue
                if any(f in first_goals for f in op.add):
                    helpful.add((op.kind, op.action))
        return Estimate(len(chosen), frozenset(helpful))
