"""Desires and the goal reasoner: which desire the agent should pursue now.

A desire is a goal (predicate literals to make true) with a priority, a deadline (an
absolute simulated time once the desire is held), a precondition that must hold to
activate it and a context that must hold all the while it is pursued.

The deadline is for planning, as in the paper: a desire not taken up by then is dropped.
The desire whose plan is executing gets `rtc_deadline` times its span (ROS2-BDI's
name), so a robot meeting its goal is not stopped midway and started over; and a BOOST
that adds a literal gives the desire the rule's span again from then for it.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Iterable, Mapping
from dataclasses import dataclass, replace

from cbdi.beliefs import Belief, BeliefSet
from cbdi_scheduler.conditions import (
    Binding,
    Condition,
    holds,
    substitute,
    substitute_belief,
)

__all__ = [
    "Desire",
    "Drop",
    "achieved",
    "boosted",
    "bound_condition",
    "drops",
    "joint",
    "ready",
    "select_desire",
]

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
    span: float = NO_DEADLINE  # the relative deadline it was taken up with
    # The name of the one intention this desire may be pursued in, with every other
    # ready desire of the same `together` and priority (`joint`); "": on its own.
    together: str = ""

    @property
    def is_joint(self) -> bool:
        """Whether this is the desire of a joint intention (`joint`), not a rule's."""
        return bool(self.together) and self.name == self.together

    def member(self, desire: Desire) -> bool:
        """Whether `desire` is pursued in this joint intention's desire."""
        return (
            self.is_joint
            and desire.together == self.together
            and desire.priority == self.priority
            and not desire.is_joint
            and set(desire.goal) <= set(self.goal)
        )

    def stretched(self, rtc_deadline: float) -> float:
        """Return the deadline of this desire while its plan executes."""
        if not math.isfinite(self.span):
            return self.deadline
        return self.deadline + (rtc_deadline - 1.0) * self.span

    def bound(self, binding: Binding) -> Desire:
        """Return this desire with `binding` substituted in its name, goal, precondition
        and context (a variable the binding lacks stays a pattern to match)."""
        return replace(
            self,
            name=substitute(self.name, binding),
            goal=tuple(substitute_belief(g, binding) for g in self.goal),
            precondition=bound_condition(self.precondition, binding),
            context=bound_condition(self.context, binding),
        )

    def due(self, now: float) -> Desire:
        """Return this desire held from `now`: a relative deadline becomes absolute."""
        return replace(self, deadline=now + self.deadline, span=self.deadline)


def bound_condition(condition: Condition, binding: Binding) -> Condition:
    """Return `condition` with `binding` substituted in its literals."""
    return tuple(
        tuple(replace(lit, belief=substitute_belief(lit.belief, binding)) for lit in clause)
        for clause in condition
    )


def boosted(desire: Desire, extra: Iterable[Belief], deadline: float | None = None) -> Desire:
    """Extend a desire's goal with more literals (the paper's BOOST: the union); if any
    is new and `deadline` is later than the desire's, the desire gets it."""
    goal = list(desire.goal)
    for literal in extra:
        if literal not in goal:
            goal.append(literal)
    if len(goal) == len(desire.goal):
        return desire
    due = desire.deadline if deadline is None else max(deadline, desire.deadline)
    return replace(desire, goal=tuple(goal), deadline=due)


def achieved(desire: Desire, beliefs: BeliefSet) -> bool:
    """Return whether every goal literal is believed."""
    return all(beliefs.holds(g) for g in desire.goal)


@dataclass(frozen=True)
class Drop:
    """A desire dropped, and why."""

    desire: str
    reason: str


def drops(
    desires: Mapping[str, Desire],
    beliefs: BeliefSet,
    now: float,
    active: str | Collection[str] | None,
    executing: bool = False,
    rtc_deadline: float = 1.0,
) -> list[Drop]:
    """Return the desires to drop: deadline passed, or an active one's context failed.

    `active`: the desire the intention pursues (or the members of a joint one); an
    active desire whose plan is `executing` has `rtc_deadline` times its span.
    """
    act = {active} if isinstance(active, str) else set(active or ())
    out = []
    for name, d in sorted(desires.items()):
        due = d.stretched(rtc_deadline) if name in act and executing else d.deadline
        if now > due:
            out.append(Drop(name, f"deadline {due:g} passed at {now:g}"))
        elif name in act and d.context and not holds(d.context, beliefs):
            out.append(Drop(name, "context no longer holds"))
    return out


def ready(desire: Desire, beliefs: BeliefSet, now: float) -> bool:
    """Whether `desire` may be pursued now: deadline ahead, not achieved, precondition
    true."""
    return (
        now <= desire.deadline
        and not achieved(desire, beliefs)
        and (not desire.precondition or holds(desire.precondition, beliefs))
    )


def select_desire(desires: Mapping[str, Desire], beliefs: BeliefSet, now: float) -> Desire | None:
    """Pick the highest-priority desire whose precondition holds and deadline is ahead.

    Ties go to the earlier deadline, then the name, so the choice is deterministic.
    """
    candidates = [d for d in desires.values() if ready(d, beliefs, now)]
    if not candidates:
        return None
    return min(candidates, key=lambda d: (-d.priority, d.deadline, d.name))


def joint(
    chosen: Desire,
    desires: Mapping[str, Desire],
    beliefs: BeliefSet,
    now: float,
    current: Desire | None = None,
) -> Desire:
    """The desire an intention pursues for the goal reasoner's `chosen`: `chosen`
    itself, or, if it may be pursued with others (`together`), the joint desire named
    by `together`: its goal the union of the goals of every ready desire of the same
    `together` and priority (one plan, one trip for several jobs), each desire still
    achieved, dropped and reported on its own. If `current` is that joint desire, its
    goal literals already achieved stay first in the goal, so that a member achieved
    does not change the goal (and make the planner search anew); a literal no member
    wants any more (given up, claimed by another agent) leaves it.
    """
    if not chosen.together:
        return chosen
    members = sorted(
        (
            d
            for d in desires.values()
            if d.together == chosen.together
            and d.priority == chosen.priority
            and not d.is_joint
            and ready(d, beliefs, now)
        ),
        key=lambda d: d.name,
    )
    wanted = [g for d in members for g in d.goal]
    goal: list[Belief] = []
    if current is not None and current.name == chosen.together:
        goal = [g for g in current.goal if g in wanted or beliefs.holds(g)]
    goal += [g for g in dict.fromkeys(wanted) if g not in goal]
    return Desire(
        name=chosen.together,
        goal=tuple(goal),
        priority=chosen.priority,
        deadline=max(d.deadline for d in members),
        span=max(d.span for d in members),
        together=chosen.together,
    )
