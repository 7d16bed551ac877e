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
    apply_start,
    apply_til,
    broken_invariant,
    initial_state,
    is_goal,
)
from cbdi_planner.task import GroundAction, Task

__all__ = ["Simulation", "simulate", "validate"]

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
    at its end (at-end condition).
    """
    by_name = {a.name: a for a in task.actions}
    actions = plan.actions if horizon is None else plan.actions[:horizon]
    current = state or initial_state(task)
    sim = Simulation(current, 0.0)
    for time, kind, index in _happenings(task, actions, current):
        sim.time = time
        step = actions[index] if index >= 0 else None
        failure = _happen(task, by_name, sim, kind, step, epsilon)
        if failure:
            sim.failed, sim.reason = index, failure
            return sim
        sim.trace.append((time, sim.state))
    sim.goal_reached = is_goal(task, sim.state)
    return sim


def validate(task: Task, plan: Plan, *, epsilon: float = 0.001) -> Simulation:
    """Simulate `plan` from the initial state; raise `PlanInvalid` unless it reaches the goal."""
    sim = simulate(task, plan, epsilon=epsilon)
    if sim.failed is not None:
        step = plan.actions[sim.failed]
        raise PlanInvalid(f"at {sim.time:.3f}: ({step.name}): {sim.reason}")
    if not sim.goal_reached:
        raise PlanInvalid(f"the plan ends at {sim.time:.3f} without reaching the goal")
    return sim


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
    by_name: dict[str, GroundAction],
    sim: Simulation,
    kind: int,
    step: ScheduledAction | None,
    epsilon: float,
) -> str:
    """Apply one happening to `sim.state`; return why it failed, or '' if it happened."""
    if step is None:
        after = apply_til(task, sim.state)
        if after is None:
            return "a timed literal breaks the invariant of a running action"
        sim.state = after
        return ""
    action = by_name.get(step.name)
    if action is None:
        return "no such action, or its conditions can never hold from this state"
    if kind == _END:
        assert action.end is not None
        after = apply_end(task, sim.state, action)
        if after is None:
            return (
                "its at-end condition does not hold"
                if action.index in sim.state.open
                else ("it is not running")
            )
        sim.state = after
        return ""
    failure = _check_duration(action, step, sim.state, epsilon)
    if failure:
        return failure
    after = apply_start(task, sim.state, action)
    if after is None:
        return _why_not_start(task, action, sim.state)
    sim.state = after
    return ""


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
