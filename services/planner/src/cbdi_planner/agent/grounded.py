"""Ground an agent's task once, then change only its initial state as beliefs change.

Grounding a map's task takes long (173 ms on campus-30x30 here, against the few
milliseconds the rest of an epoch's planner work takes), and most belief changes do not
change what it grounds to: a robot or a person moves, a cell is taken or freed. So the
task is grounded once per *key* (the objects, the static facts and the values of the
functions no action changes) and reused for every belief set with that key whose
initial state lies within what the cached grounding reaches, whatever the goal: what
grounding reaches runs from the initial state, so another goal is only compiled over
the same facts (`Grounding.aimed`; a robot that explores aims at another cell every few
epochs, and grounding anew for each cost campus-30x30's robots most of their CPU).

For the cached task to serve while people walk, it is grounded from the beliefs plus
every transient fact seen before (`Transients`: the `free` cells people
walked off): a cell taken now is free in the grounding, so its moves exist and the task
need not be grounded again when the person walks on. Relaxed reachability is monotone in
the initial state, so the task holds every action a task grounded from the current
beliefs alone would; the extra ones cannot start from the current state, and neither the
search nor its heuristic ever uses them. What grounding alone told (the goal unreachable
from these beliefs) `reaches_goal` tells from the relaxed planning graph.

A fact of a predicate that no action's condition reads (`inert`: the recycling domain's
`recycled`, which only effects make) enables nothing, so it never calls for grounding
anew: one the grounding reached is kept in the initial state, one it never numbered is
left out (a goal that needs it is aimed at anew, and that grounds). On campus-30x30 a
third of the groundings were for another robot's `(recycled ...)`, an item this one
could no longer reach.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

from cbdi.beliefs import Atom, BeliefSet, fact
from cbdi_planner.agent.problem import goal_conditions, problem_from_beliefs
from cbdi_planner.agent.transient import Transients
from cbdi_planner.errors import Unsolvable
from cbdi_planner.grounding import Grounding, grounding, static_functions
from cbdi_planner.heuristic import RelaxedPlanGraph
from cbdi_planner.pddl.ast import (
    Cond,
    Domain,
    Effect,
    ExistsCond,
    ForallCond,
    ForallEffect,
    Lit,
    OrCond,
    Problem,
    WhenEffect,
)
from cbdi_planner.reachability import fluent_predicates
from cbdi_planner.state import State, initial_state
from cbdi_planner.task import Task

__all__ = ["Groundings", "condition_predicates", "reaches_goal"]

Key = tuple[object, ...]
_NO_PROBLEM = Problem(name="", domain_name="", objects={}, init=[], init_numeric={}, goal=())


@dataclass(frozen=True, slots=True)
class _Cached:
    key: Key  # what the grounding depends on: not the goal (`Grounding.aimed`)
    grounding: Grounding
    goal: tuple[tuple[str, ...], ...]  # the goal it was grounded with


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
        self.inert = self.fluent - condition_predicates(domain)
        self._cached: _Cached | None = None
        self._last: tuple[BeliefSet, tuple[tuple[str, ...], ...], Task] | None = None
        self.grounded = 0
        self.reused = 0

    def task(
        self, beliefs: BeliefSet, goal: Sequence[Sequence[str]], held: Sequence[Atom] = ()
    ) -> Task:
        """Return the task of reaching `goal` from `beliefs`; `held`: facts that held when
        the running steps started (`held_at_start`), which the task must reach so that
        those steps and what follows them are in it, though the beliefs lack them now
        (a busy robot is not `idle`).

        Raise GoalError for a goal the domain cannot express and PlannerError (Unsolvable
        among them) as grounding does.
        """
        wanted = tuple(tuple(g) for g in goal)
        held = sorted({tuple(h) for h in held if h[0] in self.fluent} - beliefs.facts)
        last = self._last
        same = last is not None and last[0] is beliefs and last[1] == wanted
        if last is not None and same and _reaches(self._cached, held):
            return last[2]  # the same beliefs again (a warm-up, then the epoch's work)
        key, fluent_facts, values = self._parts(beliefs)
        cached = self._cached
        task = None
        if cached is not None and cached.key == key and _reaches(cached, held):
            task = self._reuse(cached, fluent_facts, values, wanted)
            self.reused += task is not None
        if task is None:
            problem = problem_from_beliefs(self.domain, beliefs, goal)
            g = grounding(self.domain, self._superset(beliefs, goal, problem, held))
            self._cached = _Cached(key, g, wanted)
            self.grounded += 1
            task = _with_init(g, fluent_facts, values, self.inert, wanted)
            assert task is not None, "a task grounded from a superset reaches its subset"
        self._last = (beliefs, wanted, task)
        return task

    def blocked(
        self, beliefs: BeliefSet, goal: Sequence[Sequence[str]], held: Sequence[Atom] = ()
    ) -> bool | None:
        """Tell whether `goal` is relaxed-reachable once the missing transient facts hold
        again, from the cached task; None if it cannot tell (no task for this goal).
        `held`: facts the running steps started from (as for `task`): mid-step the
        beliefs lack them (a busy robot is not `idle`), and from the beliefs alone
        nothing would reach the goal, moving things or not."""
        missing = self.transients.missing(beliefs)
        if not missing:
            return False
        cached = self._cached
        if cached is None:
            return None
        key, facts, values = self._parts(beliefs)
        if cached.key != key:
            return None
        try:
            task = self._reuse(cached, facts, values, tuple(tuple(g) for g in goal))
        except Unsolvable:  # not even with every transient fact: not for it to tell
            return None
        index = cached.grounding.fact_index
        restore = [*missing, *(tuple(h) for h in held if h[0] in self.fluent)]
        if task is None or any(f not in index for f in restore):
            return None
        restored = task.init_facts
        for f in restore:
            restored |= 1 << index[f]
        return reaches_goal(task, State(restored, task.init_nums))

    def _reuse(
        self,
        cached: _Cached,
        facts: list[Atom],
        values: dict[Atom, float],
        goal: tuple[tuple[str, ...], ...],
    ) -> Task | None:
        """The cached task from these facts and values, aiming at `goal`; None if it
        does not serve (a fact it never reaches, a goal it cannot aim at)."""
        task = _with_init(cached.grounding, facts, values, self.inert, goal)
        if task is None or cached.goal == goal:
            return task
        return cached.grounding.aimed(task, goal_conditions(self.domain, goal))

    def _parts(self, beliefs: BeliefSet) -> tuple[Key, list[Atom], dict[Atom, float]]:
        """The grounding's key for `beliefs` (what `problem_from_beliefs` would make of
        them but the fluent facts and values), their fluent facts and function values."""
        domain, fluent = self.domain, self.fluent
        known_types = set(domain.types) | {"object"}
        objects = frozenset(
            (n, t)
            for n, t in beliefs.instances.items()
            if t in known_types and n not in domain.constants
        )
        statics: list[Atom] = []
        fluents: list[Atom] = []
        for atom in beliefs.facts:
            params = domain.predicates.get(atom[0])
            if params is not None and len(params) == len(atom) - 1:
                (fluents if atom[0] in fluent else statics).append(atom)
        values = {a: v for a, v in beliefs.fluents.items() if a[0] in domain.functions}
        key = (
            objects,
            frozenset(statics),
            frozenset((a, v) for a, v in values.items() if a[0] in self.statics),
            frozenset(a for a in values if a[0] not in self.statics),
        )
        return key, fluents, values

    def _superset(
        self,
        beliefs: BeliefSet,
        goal: Sequence[Sequence[str]],
        problem: Problem,
        held: Sequence[Atom] = (),
    ) -> Problem:
        """The problem from `beliefs` plus the transient facts seen before and the facts
        `held` (only those some action changes: a static fact added would change what
        is static)."""
        missing = sorted(set(self.transients.missing(beliefs)) | set(held))
        if not missing:
            return problem
        extra = [fact(*f) for f in missing if f[0] in self.fluent]
        if not extra:
            return problem
        return problem_from_beliefs(self.domain, beliefs.adding(extra), goal)


def _reaches(cached: _Cached | None, facts: Sequence[Atom]) -> bool:
    """Whether the cached grounding reaches every one of `facts`."""
    if not facts:
        return True
    if cached is None:
        return False
    g = cached.grounding
    index = g.fact_index
    return all(f in index and g.reached >> index[f] & 1 for f in facts)


def _with_init(
    g: Grounding,
    facts: list[Atom],
    values: dict[Atom, float],
    inert: frozenset[str],
    goal: tuple[tuple[str, ...], ...],
) -> Task | None:
    """Return `g`'s task from the initial state of these fluent `facts` and function
    `values`, or None if it holds a fact the grounding never reaches (a task grounded
    from it may have more actions) that some action's condition or `goal` reads."""
    index = g.fact_index
    mask = 0
    free = 0  # inert facts: whether reached or not, they enable nothing
    named = {a[1:] if a[:1] == ("not",) else a for a in goal}
    for atom in facts:
        bit = index.get(atom)
        if bit is None:
            if atom[0] in inert and atom not in named:
                continue
            return None
        mask |= 1 << bit
        if atom[0] in inert and atom not in named:
            free |= 1 << bit
    if mask & ~g.reached & ~free:
        return None
    nums = [math.nan] * len(g.var_index)
    for head, var in g.var_index.items():
        nums[var] = values.get(head, math.nan)
    return replace(g.task, init_facts=mask, init_nums=tuple(nums))


def condition_predicates(domain: Domain) -> frozenset[str]:
    """The predicates some action's condition reads (its conditions and those of its
    conditional effects, at any time, either sign)."""
    names: set[str] = set()

    def conds(items: tuple[Cond, ...]) -> None:
        for c in items:
            if isinstance(c, Lit):
                names.add(c.atom.predicate)
            elif isinstance(c, ForallCond | ExistsCond):
                conds(c.body)
            elif isinstance(c, OrCond):
                for part in c.parts:
                    conds(part)

    def effects(items: tuple[Effect, ...]) -> None:
        for e in items:
            if isinstance(e, WhenEffect):
                conds(e.condition)
                effects(e.body)
            elif isinstance(e, ForallEffect):
                effects(e.body)

    for action in domain.actions:
        conds(action.conditions)
        effects(action.effects)
    return frozenset(names)


def reaches_goal(task: Task, state: State | None = None) -> bool:
    """Tell whether the goal is reachable from `state` (default: the initial state) in
    the relaxed planning graph (deletes ignored)."""
    graph = RelaxedPlanGraph.of(task)
    return graph.levels(state or initial_state(task), task.goal) is not None
