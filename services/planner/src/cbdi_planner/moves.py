"""The compiled core's successor generation: a task's happenings handed to it once.

`Expander.moves` and `Expander.schedule` on the compiled core (`cbdi_planner.core`) make
one call per node: `cbdi_planner_core.Moves` applies every happening the node may take
(the semantics of `cbdi_planner.state`) and returns what the `State`s and `Step`s are
built from, and one call per move puts its steps on the timeline with the happenings
certain to come (`Expander._future`). The task's snaps get their codes in a shared
`Oracle` once, for every search of a task with the same actions and timed literals.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from types import ModuleType
from typing import Any

from cbdi_planner.stn import Oracle
from cbdi_planner.task import CondEffect, NumAssign, NumCond, Snap, Task, bit_positions

__all__ = ["CompiledMoves", "goal_of", "til_snaps"]

BUILT = 3  # tasks kept (least recently used first out; campus-30x30: some 10 MB each)


def til_snaps(task: Task) -> list[Snap]:
    """The happening of each group of timed literals (it reads what it writes)."""
    return [Snap(0, 0, (), t.add, t.dele, (), (), 0, t.add | t.dele, 0, 0) for t in task.tils]


def goal_of(task: Task) -> tuple[object, ...]:
    """The task's goal as the compiled core takes a conjunction."""
    return _conj(task.goal, task.goal_neg, task.goal_num)


def _conj(pre: int, neg: int, num: tuple[NumCond, ...]) -> tuple[object, ...]:
    return (bit_positions(pre), bit_positions(neg), [(c.op, c.lhs, c.rhs) for c in num])


def _effects(add: int, dele: int, num: tuple[NumAssign, ...]) -> tuple[object, ...]:
    return (bit_positions(add), bit_positions(dele), [(a.op, a.var, a.expr) for a in num])


def _when(ce: CondEffect) -> tuple[object, ...]:
    return (_conj(ce.pre, ce.neg, ce.num_pre), _effects(ce.add, ce.dele, ce.num_eff))


def _snap(snap: Snap) -> tuple[object, ...]:
    return (
        _conj(snap.pre, snap.neg, snap.num_pre),
        _effects(snap.add, snap.dele, snap.num_eff),
        [_when(ce) for ce in snap.cond_effects],
    )


@dataclass(frozen=True, slots=True)
class CompiledMoves:
    """A task's happenings in the compiled core.

    `core`: the `cbdi_planner_core.Moves`; `oracle`: the codes of the task's snaps;
    `snaps[kind][i]`: the snap of a step of that kind (`stn.START`, `END`, `INST`: of
    action `i`; `TIL`: of group `i`).
    """

    core: Any
    oracle: Oracle
    snaps: tuple[tuple[Snap | None, ...], ...]
    tils: tuple[Snap, ...]

    @classmethod
    def of(
        cls, task: Task, module: ModuleType, needs: Callable[[Task], list[int]]
    ) -> CompiledMoves:
        """The task's compiled moves, built once per task of the same actions and timed
        literals (`needs(task)[a]`: the facts action `a` needs before it starts)."""
        key = (id(task.actions), id(task.tils), len(task.facts))
        with _LOCK:
            found = _CACHE.get(key)
            if found is not None:
                _CACHE.move_to_end(key)
                return found[0]
        built = cls._build(task, module, needs(task))
        with _LOCK:
            # the entry holds what the key's ids name, so they stay theirs
            _CACHE[key] = (built, (task.actions, task.tils))
            while len(_CACHE) > BUILT:
                _CACHE.popitem(last=False)
        return built

    @classmethod
    def _build(cls, task: Task, module: ModuleType, needs: list[int]) -> CompiledMoves:
        oracle = Oracle(module)
        tils = tuple(til_snaps(task))
        specs = []
        for a in task.actions:
            start = oracle.code(a.start)
            end = oracle.code(a.end) if a.end is not None else start
            specs.append(
                (
                    _snap(a.start),
                    _snap(a.end) if a.end is not None else None,
                    _conj(a.inv, a.inv_neg, a.inv_num),
                    a.fixed_duration,
                    list(a.duration),
                    start,
                    end,
                )
            )
        groups = [
            (t.time, bit_positions(t.add), bit_positions(t.dele), oracle.code(snap))
            for t, snap in zip(task.tils, tils, strict=True)
        ]
        core = module.Moves(
            oracle.core, specs, groups, [list(bit_positions(n)) for n in needs], len(task.facts)
        )
        starts = tuple(a.start for a in task.actions)
        ends = tuple(a.end for a in task.actions)
        return cls(core, oracle, (starts, ends, starts, tils), tils)


_CACHE: OrderedDict[tuple[object, ...], tuple[CompiledMoves, object]] = OrderedDict()
_LOCK = threading.Lock()
