"""Desires and the goal reasoner: which desire the agent should pursue now.

A desire is a goal (predicate literals to make true) with a priority, a deadline (an
absolute simulated time once the desire is held), a precondition that must hold to
activate it and a context that must keep holding while it is pursued.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace

from cbdi.beliefs import Belief, BeliefSet
from cbdi_scheduler.conditions import (
    Binding,
    Condition,
    holds,
    substitute,
    substitute_belief,
)

__all__ = ["Desire", "Drop", "achieved", "boosted", "drops", "select_desire"]

NO_DEADLINE = float("inf")


@dataclass(frozen=True)
class Desire:
    """A desire of the agent (names and goal literals may hold `{x}` placeholders)."""

    name: str
    goal: tuple[Belief, ...]
    priority: float = 0.5
    deadline: float = NO_DEADLINE
    precondition: Condition = ()
    context: Condition = ()

    def bound(self, binding: Binding) -> Desire:
        """Return this desire with `binding` substituted in its name and goal."""
        return replace(
            self,
            name=substitute(self.name, binding),
            goal=tuple(substitute_belief(g, binding) for g in self.goal),
        )

    def due(self, now: float) -> Desire:
        """Return this desire held from `now`: a relative deadline becomes absolute."""
        return replace(self, deadline=now + self.deadline)


def boosted(desire: Desire, extra: Iterable[Belief]) -> Desire:
    """Extend a desire's goal with more literals (the paper's BOOST: the union)."""
    goal = list(desire.goal)
    for literal in extra:
        if literal not in goal:
            goal.append(literal)
    return replace(desire, goal=tuple(goal))


def achieved(desire: Desire, beliefs: BeliefSet) -> bool:
    """Return whether every goal literal is believed."""
    return all(beliefs.holds(g) for g in desire.goal)


@dataclass(frozen=True)
class Drop:
    """A desire dropped, and why."""

    desire: str
    reason: str


def drops(
    desires: Mapping[str, Desire], beliefs: BeliefSet, now: float, active: str | None
) -> list[Drop]:
    """Return the desires to drop: deadline passed, or the active one's context failed."""
    out = []
    for name, d in sorted(desires.items()):
        if now > d.deadline:
            out.append(Drop(name, f"deadline {d.deadline:g} passed at {now:g}"))
        elif name == active and d.context and not holds(d.context, beliefs):
            out.append(Drop(name, "context no longer holds"))
    return out


def select_desire(desires: Mapping[str, Desire], beliefs: BeliefSet, now: float) -> Desire | None:
    """Pick the highest-priority desire whose precondition holds and deadline is ahead.

    Ties go to the earlier deadline, then the name, so the choice is deterministic.
    """
    ready = [
        d
        for d in desires.values()
        if now <= d.deadline
        and not achieved(d, beliefs)
        and (not d.precondition or holds(d.precondition, beliefs))
    ]
    if not ready:
        return None
    return min(ready, key=lambda d: (-d.priority, d.deadline, d.name))
