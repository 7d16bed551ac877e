"""Tell a goal blocked by something that moves from a goal nothing can reach.

A domain declares which of its predicates moving things change (the agent file's
`transient_predicates`: a cell `free` or `clear`, which people, carts and robots take
away from the cells they stand on). The planner remembers every such fact it has seen
believed. When a search fails, it asks whether the goal would be reachable in the
relaxed planning graph (delete effects ignored, durative actions as their start and
end) if those facts held again: if so, the failure is *blocked* (a person in a doorway,
a robot parked at a door) and the scheduler waits for the obstacle to move;
if not, no change of moving obstacles can help and the goal is unsolvable.

The test is an over-approximation by design: a goal reported unsolvable is unsolvable
whatever moves; one reported blocked may still fail for other reasons, and is then given
up at its deadline.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

from cbdi.beliefs import Atom, BeliefSet, fact
from cbdi_planner.agent.problem import GoalError, problem_from_beliefs
from cbdi_planner.errors import PlannerError
from cbdi_planner.grounding import ground
from cbdi_planner.heuristic import RelaxedPlanGraph
from cbdi_planner.pddl.ast import Domain
from cbdi_planner.state import initial_state

__all__ = ["Transients"]


class Transients:
    """The transient facts an agent has believed, and the blocked-or-unsolvable test."""

    def __init__(self, predicates: Iterable[str] = ()) -> None:
        self.predicates = frozenset(predicates)
        self.seen: set[Atom] = set()
        self._facts: frozenset[Atom] | None = None

    def see(self, beliefs: BeliefSet) -> None:
        """Remember the transient facts of `beliefs`."""
        if not self.predicates or beliefs.facts is self._facts:
            return
        self._facts = beliefs.facts
        new = {f for f in beliefs.facts if f[0] in self.predicates} - self.seen
        if new:  # a new set, never changed in place: a search thread may be reading it
            self.seen = self.seen | new

    def missing(self, beliefs: BeliefSet) -> list[Atom]:
        """Return the transient facts seen before that `beliefs` lack (over known objects)."""
        known = beliefs.instances
        return sorted(
            f for f in self.seen if f not in beliefs.facts and all(a in known for a in f[1:])
        )

    def blocked(
        self,
        domain: Domain,
        beliefs: BeliefSet,
        goal: Sequence[Sequence[str]],
        held: Sequence[Atom] = (),
    ) -> bool:
        """Return whether `goal` is reachable once the missing transient facts hold again.

        `held`: the facts the running steps started from (`held_at_start`). Mid-step the
        beliefs lack some (a busy robot is not `idle`), and from them alone no action
        could start: every failure mid-step would look unsolvable. With them the running
        steps, and what they leave, are in the relaxed graph (an over-approximation of
        the committed state, as the test is)."""
        missing = self.missing(beliefs)
        if not missing:
            return False
        relaxed = beliefs.adding(fact(*f) for f in [*missing, *held])
        try:
            task = ground(domain, problem_from_beliefs(domain, relaxed, goal))
        except (GoalError, PlannerError):
            return False
        graph = RelaxedPlanGraph.of(task)
        return graph.levels(initial_state(task), task.goal) is not None
