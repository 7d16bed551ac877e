"""States and the semantics of happenings: start, end, instantaneous action, timed literal.

A state holds the true facts (a bitmask), the numeric values, the durative actions
running now, and how many groups of timed initial literals have already happened.
Every transition checks the invariants (`over all` conditions) of the running actions
after its effects: a happening may not break a running action's invariant.
"""

from __future__ import annotations

from dataclasses import dataclass

from cbdi_planner.task import GroundAction, Snap, Task, holds

__all__ = [
    "State",
    "apply_end",
    "apply_instant",
    "apply_start",
    "apply_til",
    "broken_invariant",
    "initial_state",
    "is_goal",
]


@dataclass(frozen=True, slots=True)
class State:
    """A search state; `open` lists running ground actions by index, sorted."""

    facts: int
    nums: tuple[float, ...]
    open: tuple[int, ...] = ()
    til: int = 0

    def key(self) -> tuple[int, tuple[float, ...], tuple[int, ...], int]:
        """Return the identity used for duplicate detection (timing is not part of it)."""
        return (self.facts, self.nums, self.open, self.til)


def initial_state(task: Task) -> State:
    """Return the state at time 0 (before any timed literal)."""
    return State(task.init_facts, task.init_nums)


def is_goal(task: Task, state: State) -> bool:
    """Tell whether the goal holds and no action is still running."""
    return not state.open and holds(
        task.goal, task.goal_neg, task.goal_num, state.facts, state.nums
    )


def broken_invariant(
    task: Task, facts: int, nums: tuple[float, ...], running: tuple[int, ...]
) -> GroundAction | None:
    """Return a running action whose invariant does not hold, or None."""
    for index in running:
        action = task.actions[index]
        if not holds(action.inv, action.inv_neg, action.inv_num, facts, nums):
            return action
    return None


def _fire(snap: Snap, state: State) -> tuple[int, tuple[float, ...]] | None:
    if (snap.pre & ~state.facts) or (snap.neg & state.facts):
        return None
    if snap.num_pre and not all(c.holds(state.nums) for c in snap.num_pre):
        return None
    return snap.apply(state.facts, state.nums)


def apply_start(task: Task, state: State, action: GroundAction) -> State | None:
    """Start a durative action (or apply an instantaneous one); None if not applicable."""
    if action.end is None:
        return apply_instant(task, state, action)
    if action.index in state.open:
        return None  # no self-overlap: two copies would share one end condition
    fired = _fire(action.start, state)
    if fired is None:
        return None
    facts, nums = fired
    running = tuple(sorted((*state.open, action.index)))
    if broken_invariant(task, facts, nums, running) is not None:
        return None
    return State(facts, nums, running, state.til)


def apply_end(task: Task, state: State, action: GroundAction) -> State | None:
    """End a running durative action; None if its end condition does not hold."""
    assert action.end is not None
    if action.index not in state.open:
        return None
    fired = _fire(action.end, state)
    if fired is None:
        return None
    facts, nums = fired
    running = tuple(i for i in state.open if i != action.index)
    if broken_invariant(task, facts, nums, running) is not None:
        return None
    return State(facts, nums, running, state.til)


def apply_instant(task: Task, state: State, action: GroundAction) -> State | None:
    """Apply an instantaneous action; None if not applicable."""
    fired = _fire(action.start, state)
    if fired is None:
        return None
    facts, nums = fired
    if broken_invariant(task, facts, nums, state.open) is not None:
        return None
    return State(facts, nums, state.open, state.til)


def apply_til(task: Task, state: State) -> State | None:
    """Let the next group of timed initial literals happen; None if none is left."""
    if state.til >= len(task.tils):
        return None
    til = task.tils[state.til]
    facts = (state.facts & ~til.dele) | til.add
    if broken_invariant(task, facts, state.nums, state.open) is not None:
        return None
    return State(facts, state.nums, state.open, state.til + 1)
