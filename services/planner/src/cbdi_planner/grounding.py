"""Ground a parsed domain and problem into a `Task`.

Three passes: lifted relaxed reachability finds the action instances worth creating;
compilation turns them into bitmask snap actions with statics folded away; a ground
relaxed reachability with snap semantics then drops instances that can never start
or never end.

A disjunctive goal becomes a fact of the planner's own, `(#goal)`, that one internal
instantaneous action per disjunct adds and every other happening deletes: it holds at
the end of a plan exactly when a disjunct does. The search and its heuristic keep a
conjunctive goal; plans never show the internal actions (plan.py), and simulating a
plan tries them at its end (simulate.py).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass

from cbdi_planner.compile import Compiler
from cbdi_planner.dnf import Conj
from cbdi_planner.effects import Effs, build_snap
from cbdi_planner.errors import Unsolvable
from cbdi_planner.pddl.ast import Cond, Domain, NumEffect, Problem
from cbdi_planner.reachability import (
    GAtom,
    Objects,
    _walk_effects,
    fluent_predicates,
    reachable_instances,
)
from cbdi_planner.task import INTERNAL, GroundAction, Snap, Task, TimedLiterals

__all__ = ["Grounding", "ground", "grounding", "static_functions"]


@dataclass(frozen=True, slots=True)
class Grounding:
    """A ground task and what it takes to give it another initial state.

    `fact_index` and `var_index` map ground atoms and function heads to their bit and
    variable; `fluent` names the predicates some effect changes (the rest were folded
    away); `reached` holds every fact relaxed-reachable from the initial state (snap
    semantics, as the pruning found them). A task for an initial state within `reached`
    (and with the same objects and static facts) has no action this one lacks, whatever
    its goal (`aimed`).
    """

    task: Task
    fact_index: Mapping[GAtom, int]
    var_index: Mapping[tuple[str, ...], int]
    fluent: frozenset[str]
    reached: int
    compiler: Compiler | None = None  # what numbered the facts: it compiles other goals
    disjunctive: bool = False  # its actions carry the goal's `(#goal)`: for it alone

    def aimed(self, task: Task, goal: tuple[Cond, ...], file: str = "") -> Task | None:
        """`task` (this grounding's, another initial state maybe) aiming at `goal`.

        Grounding does not depend on the goal (reachability runs from the initial
        state), so a conjunctive goal only needs compiling over these facts. None when
        that is not enough: this grounding carries a disjunctive goal of its own, `goal`
        is disjunctive, or it reads a numeric variable no action numbered. Raise
        Unsolvable for a goal that can never hold, as grounding does.
        """
        compiler = self.compiler
        if compiler is None or self.disjunctive:
            return None
        numbered = len(compiler.var_index)
        goals = compiler.goal(goal, file)
        if len(compiler.var_index) != numbered:
            for key in list(compiler.var_index)[numbered:]:  # leave the numbering as it was
                del compiler.var_index[key]
            return None
        if not goals:
            raise Unsolvable("the goal can never hold (a static or unreachable fact is wrong)")
        if len(goals) > 1:
            return None
        return dataclasses.replace(
            task, goal=goals[0].pre, goal_neg=goals[0].neg, goal_num=tuple(goals[0].num)
        )


def static_functions(domain: Domain) -> set[str]:
    """Return the functions no action changes (their values are folded into the task)."""
    changed = {
        e.head.name
        for a in domain.actions
        for e in _walk_effects(a.effects)
        if isinstance(e, NumEffect)
    }
    return set(domain.functions) - changed


def ground(domain: Domain, problem: Problem) -> Task:
    """Ground `problem`; raise `Unsolvable` if the goal mentions an unreachable fact."""
    return grounding(domain, problem).task


def grounding(domain: Domain, problem: Problem) -> Grounding:
    """Ground `problem` and keep its indices; raise `Unsolvable` as `ground` does."""
    objects = Objects(domain, problem)
    fluent = fluent_predicates(domain, problem)
    instances, atoms = reachable_instances(domain, problem, objects, fluent)
    static_atoms = {(a.predicate, *a.args) for a in problem.init if a.predicate not in fluent}
    fluent_atoms = {a for a in atoms if a[0] in fluent}
    compiler = Compiler(
        objects,
        static_atoms,
        fluent_atoms,
        problem.init_numeric,
        static_functions(domain),
        domain.file,
    )
    actions: list[GroundAction] = []
    for inst in instances:
        actions.extend(compiler.actions(inst, len(actions)))
    goals = compiler.goal(problem.goal, problem.file)
    if not goals:
        raise Unsolvable("the goal can never hold (a static or unreachable fact is wrong)")
    tils = _timed_literals(problem, compiler)
    goal = goals[0]
    if len(goals) > 1:
        goal, actions, tils = _disjunctive_goal(compiler, goals, actions, tils)
    init_facts = 0
    for atom in problem.init:
        index = compiler.fact_index.get((atom.predicate, *atom.args))
        if index is not None:
            init_facts |= 1 << index
    nums = [math.nan] * len(compiler.var_index)
    for key, var in compiler.var_index.items():
        nums[var] = compiler.init_numeric.get(key, math.nan)
    task = Task(
        facts=compiler.facts,
        num_vars=["(" + " ".join(k) + ")" for k in compiler.var_index],
        actions=actions,
        init_facts=init_facts,
        init_nums=tuple(nums),
        goal=goal.pre,
        goal_neg=goal.neg,
        goal_num=tuple(goal.num),
        tils=tils,
        name=problem.name,
    )
    task.actions, reached = _prune(task)
    return Grounding(
        task,
        compiler.fact_index,
        compiler.var_index,
        frozenset(fluent),
        reached,
        compiler,
        len(goals) > 1,
    )


def _disjunctive_goal(
    compiler: Compiler,
    goals: list[Conj],
    actions: list[GroundAction],
    tils: list[TimedLiterals],
) -> tuple[Conj, list[GroundAction], list[TimedLiterals]]:
    """Compile a disjunctive goal into `(#goal)`, added by one internal action per
    disjunct and deleted by every other happening (so it holds only when a disjunct
    holds after the last one)."""
    bit = compiler.new_fact(f"{INTERNAL}goal")
    out = [_deleting(a, bit) for a in actions]
    reached = Effs(add=bit)
    for k, conj in enumerate(goals):
        snap = build_snap(conj, reached, None)
        out.append(GroundAction(len(out), f"{INTERNAL}goal {k}", snap, None, 0, 0, (), (), None))
    tils = [TimedLiterals(t.time, t.add, t.dele | bit) for t in tils]
    return Conj(pre=bit), out, tils


def _deleting(action: GroundAction, bit: int) -> GroundAction:
    """Make every snap of `action` delete `bit`, without counting it as a write: the
    goal fact orders nothing when the plan is lifted to a partial order."""

    def snap(s: Snap) -> Snap:
        return dataclasses.replace(s, dele=s.dele | bit)

    end = snap(action.end) if action.end is not None else None
    return dataclasses.replace(action, start=snap(action.start), end=end)


def _timed_literals(problem: Problem, compiler: Compiler) -> list[TimedLiterals]:
    by_time: dict[float, list[int]] = {}
    for when, lit in sorted(problem.timed_literals, key=lambda item: item[0]):
        index = compiler.fact_index.get((lit.atom.predicate, *lit.atom.args))
        if index is None:
            continue
        masks = by_time.setdefault(when, [0, 0])
        masks[0 if lit.positive else 1] |= 1 << index
    return [TimedLiterals(t, add, dele) for t, (add, dele) in sorted(by_time.items())]


def _prune(task: Task) -> tuple[list[GroundAction], int]:
    """Keep the actions whose start and end are relaxed-reachable, renumbered; and the
    facts they reach.

    Starts and ends are reached separately, as snap actions: an end may need what
    another action's start gives later (required concurrency). Deletes and numeric
    conditions are ignored, so this never drops a useful action.
    """
    reached = task.init_facts
    for til in task.tils:
        reached |= til.add
    started: set[int] = set()
    live: set[int] = set()
    changed = True
    while changed:
        changed = False
        for action in task.actions:
            if action.index in live:
                continue
            if action.index not in started:
                start = action.start
                if start.pre & ~reached:
                    continue
                started.add(action.index)
                reached |= start.add | _cond_adds(start)
                changed = True
            end = action.end
            if end is not None:
                if (action.inv | end.pre) & ~reached:
                    continue
                reached |= end.add | _cond_adds(end)
            live.add(action.index)
            changed = True
    kept = [a for a in task.actions if a.index in live]
    return [_renumber(a, i) for i, a in enumerate(kept)], reached


def _cond_adds(snap: object) -> int:
    total = 0
    for ce in getattr(snap, "cond_effects", ()):
        total |= ce.add
    return total


def _renumber(action: GroundAction, index: int) -> GroundAction:
    return GroundAction(
        index,
        action.name,
        action.start,
        action.end,
        action.inv,
        action.inv_neg,
        action.inv_num,
        action.duration,
        action.fixed_duration,
    )
