"""Simulate a time-triggered plan from a state, and validate plans.

The executor's checks and the failure forecast (issue 4) need exactly this: apply the
plan's happenings (starts, ends, instantaneous actions, timed literals) in time order
from a state and report the first one that cannot happen, and why.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from cbdi_planner.errors import PlanInvalid
from cbdi_planner.plan import Plan, ScheduledAction
from cbdi_planner.state import (
    State,
    apply_end,
    apply_instant,
    apply_start,
    apply_til,
    broken_invariant,
    initial_state,
    is_goal,
)
from cbdi_planner.task import GroundAction, Task

__all__ = ["Simulation", "goal_reached", "simulate", "validate"]

_TOLERANCE = 1e-6
# At one time: ends first, then timed literals, then starts (as VAL orders happenings
# that an epsilon-separated plan puts at the same time only when they do not interfere).
_END, _TIL, _START = 0, 1, 2


@dataclass(slots=True)
class Simulation:
    """What happened: `failed` is the index (in `plan.actions`) of the first action that
    could not start or end, or None; `trace` lists `(time, state)` after each happening.
    """

    state: State
    time: float
    failed: int | None = None
    reason: str = ""
    goal_reached: bool = False
    trace: list[tuple[float, State]] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """Tell whether every simulated action could start and end."""
        return self.failed is None


def simulate(
    task: Task,
    plan: Plan,
    state: State | None = None,
    *,
    horizon: int | None = None,
    epsilon: float = 0.001,
) -> Simulation:
    """Run `plan` (or only its first `horizon` actions) from `state` (default: the
    initial state, timed literals counted from time 0).

    An action is checked at its start (at-start condition, duration constraints, no
    running invariant broken), while it runs (its invariant after every happening) and
    at its end (at-end condition). A name several ground actions share (one per
    disjunct of a condition) may be any of them: the simulation follows every one that
    can happen, so `state` is the first of the states the plan may be in.
    """
    variants = _by_name(task)
    actions = plan.actions if horizon is None else plan.actions[:horizon]
    current = state or initial_state(task)
    sim = Simulation(current, 0.0)
    frontier = [current]
    for time, kind, index in _happenings(task, actions, current):
        sim.time = time
        step = actions[index] if index >= 0 else None
        after = _happen(task, variants, frontier, kind, step, epsilon)
        if not after:
            sim.failed = index
            sim.reason = _why_not(task, variants, frontier[0], kind, step, epsilon)
            return sim
        frontier = after
        sim.state = frontier[0]
        sim.trace.append((time, sim.state))
    reached = [s for s in frontier if goal_reached(task, s)]
    sim.goal_reached = bool(reached)
    if reached:
        sim.state = reached[0]
    return sim


def goal_reached(task: Task, state: State) -> bool:
    """Tell whether the problem's goal holds and no action runs; a disjunctive goal
    holds when one of its internal actions would reach the search's goal fact."""
    if is_goal(task, state):
        return True
    return any(
        (after := apply_instant(task, state, action)) is not None and is_goal(task, after)
        for action in task.actions
        if action.internal
    )


def validate(task: Task, plan: Plan, *, epsilon: float = 0.001) -> Simulation:
    """Simulate `plan` from the initial state; raise `PlanInvalid` unless it reaches the goal."""
    sim = simulate(task, plan, epsilon=epsilon)
    if sim.failed is not None:
        step = plan.actions[sim.failed]
        raise PlanInvalid(f"at {sim.time:.3f}: ({step.name}): {sim.reason}")
    if not sim.goal_reached:
        raise PlanInvalid(f"the plan ends at {sim.time:.3f} without reaching the goal")
    return sim


def _by_name(task: Task) -> dict[str, list[GroundAction]]:
    out: dict[str, list[GroundAction]] = {}
    for action in task.actions:
        if not action.internal:
            out.setdefault(action.name, []).append(action)
    return out


def _happenings(
    task: Task, actions: tuple[ScheduledAction, ...], state: State
) -> list[tuple[float, int, int]]:
    out = [(til.time, _TIL, -1) for til in task.tils[state.til :]]
    for index, step in enumerate(actions):
        out.append((step.time, _START, index))
        if step.duration is not None:
            out.append((step.time + step.duration, _END, index))
    out.sort(key=lambda h: (round(h[0] / _TOLERANCE), h[1], h[2]))
    return out


def _happen(
    task: Task,
    variants: dict[str, list[GroundAction]],
    frontier: list[State],
    kind: int,
    step: ScheduledAction | None,
    epsilon: float,
) -> list[State]:
    """Return the states one happening can lead to from any state of `frontier`."""
    out: dict[tuple[object, ...], State] = {}
    for state in frontier:
        if step is None:
            after: list[State | None] = [apply_til(task, state)]
        elif kind == _END:
            running = [a for a in variants.get(step.name, ()) if a.index in state.open]
            after = [apply_end(task, state, a) for a in running]
        else:
            after = [
                apply_start(task, state, a)
                for a in variants.get(step.name, ())
                if not _check_duration(a, step, state, epsilon)
            ]
        for new in after:
            if new is not None:
                out.setdefault(new.key(), new)
    return list(out.values())


def _why_not(
    task: Task,
    variants: dict[str, list[GroundAction]],
    state: State,
    kind: int,
    step: ScheduledAction | None,
    epsilon: float,
) -> str:
    """Say why a happening cannot happen from `state` (the first alternative's reason)."""
    if step is None:
        return "a timed literal breaks the invariant of a running action"
    candidates = variants.get(step.name)
    if not candidates:
        return "no such action, or its conditions can never hold from this state"
    action = candidates[0]
    if kind == _END:
        if any(a.index in state.open for a in candidates):
            return "its at-end condition does not hold"
        return "it is not running"
    reason = _check_duration(action, step, state, epsilon) or _why_not_start(task, action, state)
    if len(candidates) == 1:
        return reason
    return f"none of its {len(candidates)} alternative conditions holds (the first: {reason})"


def _check_duration(
    action: GroundAction, step: ScheduledAction, state: State, epsilon: float
) -> str:
    if action.durative != (step.duration is not None):
        return (
            "durative action without duration"
            if action.durative
            else ("instantaneous action given a duration")
        )
    if step.duration is None:
        return ""
    low, high = action.duration_bounds(state.nums, epsilon)
    if step.duration < low - _TOLERANCE or step.duration > high + _TOLERANCE:
        return f"duration {step.duration:g} outside [{low:g}, {high:g}]"
    return ""


def _why_not_start(task: Task, action: GroundAction, state: State) -> str:
    if action.index in state.open:
        return "it is already running"
    snap = action.start
    missing = task.fact_names(snap.pre & ~state.facts)
    if missing:
        return "its condition does not hold: " + ", ".join(missing)
    present = task.fact_names(snap.neg & state.facts)
    if present:
        return "its condition does not hold: " + ", ".join(f"(not {p})" for p in present)
    if snap.num_pre and not all(c.holds(state.nums) for c in snap.num_pre):
        return "a numeric condition does not hold"
    facts, nums = snap.apply(state.facts, state.nums)
    running = tuple(sorted((*state.open, action.index)))
    broken = broken_invariant(task, facts, nums, running)
    if broken is action:
        missing = task.fact_names(action.inv & ~facts)
        present = task.fact_names(action.inv_neg & facts)
        what = ", ".join([*missing, *(f"(not {p})" for p in present)]) or "a numeric condition"
        return f"its over-all condition does not hold: {what}"
    if broken is not None:
        return f"it breaks the over-all condition of ({broken.name})"
    return "it cannot start"
