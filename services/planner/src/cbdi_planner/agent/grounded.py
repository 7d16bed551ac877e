"""Ground an agent's task once, then change only its initial state as beliefs change.

Grounding a map's task takes long (173 ms on campus-30x30 here, against the few
milliseconds the rest of an epoch's planner work takes), and most belief changes do not
change what it grounds to: a robot or a person moves, a cell is taken or freed. So the
task is grounded once per *key* (the goal, the objects, the static facts and the values
of the functions no action changes) and reused for every belief set with that key whose
initial state lies within what the cached grounding reaches.

For the cached task to serve while people walk, it is grounded from the beliefs plus
every transient fact seen before (`Transients`: for recycling, the `free` cells people
walked off): a cell taken now is free in the grounding, so its moves exist and the task
need not be grounded again when the person walks on. Relaxed reachability is monotone in
the initial state, so the task holds every action a task grounded from the current
beliefs alone would; the extra ones cannot start from the current state, and neither the
search nor its heuristic ever uses them. What grounding alone told (the goal unreachable
from these beliefs) `reaches_goal` tells from the relaxed planning graph.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

from cbdi.beliefs import BeliefSet, fact
from cbdi_planner.agent.problem import problem_from_beliefs
from cbdi_planner.agent.transient import Transients
from cbdi_planner.grounding import Grounding, grounding, static_functions
from cbdi_planner.heuristic import RelaxedPlanGraph
from cbdi_planner.pddl.ast import Domain, Problem
from cbdi_planner.reachability import fluent_predicates
from cbdi_planner.state import State, initial_state
from cbdi_planner.task import Task

__all__ = ["Groundings", "reaches_goal"]

Key = tuple[object, ...]
_NO_PROBLEM = Problem(name="", domain_name="", objects={}, init=[], init_numeric={}, goal=())


@dataclass(frozen=True, slots=True)
class _Cached:
    key: Key
    grounding: Grounding


class Groundings:
    """One agent's grounded task, kept while only the initial state changes.

    `grounded` and `reused` count what `task` did (the benchmarks print them).
    """

    def __init__(self, domain: Domain, transients: Transients | None = None) -> None:
        self.domain = domain
        self.transients = transients or Transients()
        self.statics = frozenset(static_functions(domain))
        # Beliefs have no timed literals: the fluent predicates are the domain's.
        self.fluent = frozenset(fluent_predicates(domain, _NO_PROBLEM))
        self._cached: _Cached | None = None
        self.grounded = 0
        self.reused = 0

    def task(self, beliefs: BeliefSet, goal: Sequence[Sequence[str]]) -> Task:
        """Return the task of reaching `goal` from `beliefs`.

        Raise GoalError for a goal the domain cannot express and PlannerError (Unsolvable
        among them) as grounding does.
        """
        problem = problem_from_beliefs(self.domain, beliefs, goal)
        key = self._key(problem, goal)
        cached = self._cached
        if cached is not None and cached.key == key:
            task = _with_init(cached.grounding, problem)
            if task is not None:
                self.reused += 1
                return task
        g = grounding(self.domain, self._superset(beliefs, goal, problem))
        self._cached = _Cached(key, g)
        self.grounded += 1
        task = _with_init(g, problem)
        assert task is not None, "a task grounded from a superset reaches its subset"
        return task

    def blocked(self, beliefs: BeliefSet, goal: Sequence[Sequence[str]]) -> bool | None:
        """Tell whether `goal` is relaxed-reachable once the missing transient facts hold
        again, from the cached task; None if it cannot tell (no task for this goal)."""
        missing = self.transients.missing(beliefs)
        if not missing:
            return False
        cached = self._cached
        if cached is None:
            return None
        problem = problem_from_beliefs(self.domain, beliefs, goal)
        if cached.key != self._key(problem, goal):
            return None
        task = _with_init(cached.grounding, problem)
        index = cached.grounding.fact_index
        if task is None or any(f not in index for f in missing):
            return None
        restored = task.init_facts
        for f in missing:
            restored |= 1 << index[f]
        return reaches_goal(task, State(restored, task.init_nums))

    def _key(self, problem: Problem, goal: Sequence[Sequence[str]]) -> Key:
        fluent = self.fluent
        nums = problem.init_numeric
        return (
            tuple(tuple(g) for g in goal),
            frozenset(problem.objects.items()),
            frozenset((a.predicate, *a.args) for a in problem.init if a.predicate not in fluent),
            frozenset((h, v) for h, v in nums.items() if h.name in self.statics),
            frozenset(h for h in nums if h.name not in self.statics),
        )

    def _superset(
        self, beliefs: BeliefSet, goal: Sequence[Sequence[str]], problem: Problem
    ) -> Problem:
        """The problem from `beliefs` plus the transient facts seen before (only those
        some action changes: a static fact added would change what is static)."""
        missing = self.transients.missing(beliefs)
        if not missing:
            return problem
        extra = [fact(*f) for f in missing if f[0] in self.fluent]
        if not extra:
            return problem
        return problem_from_beliefs(self.domain, beliefs.adding(extra), goal)


def _with_init(g: Grounding, problem: Problem) -> Task | None:
    """Return `g`'s task from `problem`'s initial state, or None if that state holds a
    fact the grounding never reaches (a task grounded from it may have more actions)."""
    index, fluent = g.fact_index, g.fluent
    facts = 0
    for atom in problem.init:
        if atom.predicate not in fluent:
            continue
        bit = index.get((atom.predicate, *atom.args))
        if bit is None:
            return None
        facts |= 1 << bit
    if facts & ~g.reached:
        return None
    values = {(h.name, *h.args): v for h, v in problem.init_numeric.items()}
    nums = [math.nan] * len(g.var_index)
    for head, var in g.var_index.items():
        nums[var] = values.get(head, math.nan)
    return replace(g.task, init_facts=facts, init_nums=tuple(nums))


def reaches_goal(task: Task, state: State | None = None) -> bool:
    """Tell whether the goal is reachable from `state` (default: the initial state) in
    the relaxed planning graph (deletes ignored)."""
    graph = RelaxedPlanGraph(task)
    return graph.levels(state or initial_state(task), task.goal) is not None
