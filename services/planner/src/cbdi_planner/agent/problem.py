"""Turn an agent's beliefs and goal into a planning problem over the agent's domain.

Objects are the believed instances whose type the domain knows; the initial state is
every believed fact and function value the domain declares (anything else the agent
believes, such as bookkeeping facts of its rules, is left out); the goal is the
conjunction of the goal atoms.
"""

from __future__ import annotations

from collections.abc import Sequence
from types import MappingProxyType

from cbdi.beliefs import BeliefSet
from cbdi_planner.pddl.ast import INST, Atom, Domain, FHead, Lit, Problem

__all__ = [
    "GoalError",
    "beliefs_from_problem",
    "check_goal",
    "goal_conditions",
    "goal_of",
    "problem_from_beliefs",
]


class GoalError(ValueError):
    """A goal atom the domain cannot express (unknown predicate, wrong arity)."""


def check_goal(domain: Domain, goal: Sequence[Sequence[str]]) -> list[Atom]:
    """Return the goal's atoms; raise GoalError for one the domain cannot express."""
    atoms = []
    for g in goal:
        if not g:
            raise GoalError("an empty goal atom")
        name, args = g[0], tuple(g[1:])
        params = domain.predicates.get(name)
        if params is None:
            raise GoalError(f"goal ({' '.join(g)}): the domain has no predicate {name!r}")
        if len(params) != len(args):
            raise GoalError(f"goal ({' '.join(g)}): {name} takes {len(params)} arguments")
        atoms.append(Atom(name, args))
    return atoms


def problem_from_beliefs(
    domain: Domain, beliefs: BeliefSet, goal: Sequence[Sequence[str]], name: str = "beliefs"
) -> Problem:
    """Return the problem of reaching `goal` from `beliefs`."""
    conditions = goal_conditions(domain, goal)
    known_types = set(domain.types) | {"object"}
    objects: dict[str, tuple[str, ...]] = {
        n: (t,)
        for n, t in beliefs.instances.items()
        if t in known_types and n not in domain.constants
    }
    init = [
        Atom(a[0], tuple(a[1:]))
        for a in sorted(beliefs.facts)
        if a[0] in domain.predicates and len(a) - 1 == len(domain.predicates[a[0]])
    ]
    numeric = {
        FHead(a[0], tuple(a[1:])): v
        for a, v in sorted(beliefs.fluents.items())
        if a[0] in domain.functions
    }
    return Problem(
        name=name,
        domain_name=domain.name,
        objects=objects,
        init=init,
        init_numeric=numeric,
        goal=conditions,
    )


def goal_conditions(domain: Domain, goal: Sequence[Sequence[str]]) -> tuple[Lit, ...]:
    """Return `goal` as the problem's goal condition (`problem_from_beliefs`'s)."""
    return tuple(Lit(a, True, INST) for a in check_goal(domain, goal))


def beliefs_from_problem(problem: Problem) -> BeliefSet:
    """Return what a PDDL problem says holds at its start, as beliefs.

    Objects become instances of their (first) type, the init facts and function values
    beliefs; timed initial literals have no belief counterpart and are refused.
    """
    if problem.timed_literals:
        raise GoalError(f"{problem.file}: timed initial literals cannot be beliefs")
    instances = {name: types[0] if types else "object" for name, types in problem.objects.items()}
    facts = frozenset((a.predicate, *a.args) for a in problem.init)
    fluents = {(h.name, *h.args): v for h, v in problem.init_numeric.items()}
    return BeliefSet(MappingProxyType(instances), facts, MappingProxyType(fluents))


def goal_of(problem: Problem) -> list[list[str]]:
    """Return the problem's goal as ground atoms; only a conjunction of atoms qualifies."""
    goal = []
    for cond in problem.goal:
        if not isinstance(cond, Lit) or not cond.positive or cond.atom.predicate == "=":
            raise GoalError(
                f"{problem.file}: the goal must be a conjunction of atoms for the continual"
                f" planner (found {cond})"
            )
        goal.append([cond.atom.predicate, *cond.atom.args])
    return goal
