"""The execution simulator and the failure forecast (the paper's Section III-C).

From the executing plan and each step's status, `commit` finds the committed actions
(every step that started, then more until at least `min_commit_steps` not yet finished
are committed) and the committed state: the current beliefs with the committed actions
simulated on them. `forecast` simulates the rest of the plan from there (or only its next
`horizon` actions, the paper's proposed refinement) and classifies the outcome.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from cbdi_planner.plan import Plan, ScheduledAction
from cbdi_planner.simulate import simulate
from cbdi_planner.state import State
from cbdi_planner.task import GroundAction, Task, holds

__all__ = [
    "COMMITTED_FAILS",
    "FAILS_LATER",
    "HOLDS",
    "Commitment",
    "Forecast",
    "commit",
    "forecast",
]

COMMITTED_FAILS = "fails_in_committed"  # nothing to do: execution will report it
FAILS_LATER = "fails_after_committed"  # search again from the committed state
HOLDS = "holds"  # start the improver

DONE = ("succeeded",)
STARTED = ("running", "succeeded")


@dataclass(frozen=True, slots=True)
class Commitment:
    """`count` committed steps of the plan; `running` of them started but not finished;
    `state` is the committed state (None if simulating them failed: `reason` says why)."""

    count: int
    finished: int
    state: State | None
    reason: str = ""


@dataclass(frozen=True, slots=True)
class Forecast:
    """The outcome class, the failing step's index in the plan (or None), and why."""

    kind: str
    failed: int | None
    reason: str
    commitment: Commitment


def _force(task: Task, state: State, name: str) -> State | None:
    """Apply an already started action's effects (the world decided it could start; the
    beliefs may already show part of its effects); None if no copy of it fits.

    A name split into copies, one per disjunct of its conditions, means the copy that
    applies in `state`: its start condition holds and, for a durative one, its invariant
    and end condition hold after its start effects (which copy's effects happen depends
    on what held at its start). Failing that, the copy whose start condition holds but
    for the facts its start changes (beliefs that already show them). A lone copy is
    forced unchecked.
    """
    copies = [a for a in task.actions if a.name == name and not a.internal]
    if len(copies) > 1:
        copies = [a for a in copies if _fits(a, state, False)] or [
            a for a in copies if _fits(a, state, True)
        ]
    if not copies:
        return None
    action = copies[0]
    facts, nums = action.start.apply(state.facts, state.nums)
    if action.end is not None:
        facts, nums = action.end.apply(facts, nums)
    return State(facts, nums, state.open, state.til)


def _fits(action: GroundAction, state: State, started: bool) -> bool:
    """Tell whether `action` can start in `state` and, if durative, end right after;
    `started` leaves out the start condition's facts that the start itself changes."""
    start = action.start
    mask = ~(start.add | start.dele) if started else -1
    if not holds(start.pre & mask, start.neg & mask, start.num_pre, state.facts, state.nums):
        return False
    if action.end is None:
        return True
    facts, nums = start.apply(state.facts, state.nums)
    end = action.end
    return holds(action.inv, action.inv_neg, action.inv_num, facts, nums) and holds(
        end.pre, end.neg, end.num_pre, facts, nums
    )


def commit(
    task: Task,
    steps: Sequence[ScheduledAction],
    statuses: Mapping[int, str],
    min_commit_steps: int = 1,
) -> Commitment:
    """Return the commitment of the plan `steps` (in order) given each step's status.

    `task`'s initial state is the current beliefs, which include every finished step.
    """
    finished = 0
    while finished < len(steps) and statuses.get(finished) in DONE:
        finished += 1
    count = finished
    while count < len(steps) and statuses.get(count) in STARTED:
        count += 1
    count = min(len(steps), max(count, finished + min_commit_steps))
    state = State(task.init_facts, task.init_nums)
    for k in range(finished, count):
        if statuses.get(k) in STARTED:
            forced = _force(task, state, steps[k].name)
            if forced is None:
                return Commitment(count, finished, None, f"({steps[k].name}) is not applicable")
            state = forced
            continue
        sim = simulate(task, Plan((steps[k],)), state)
        if not sim.ok:
            return Commitment(count, finished, None, f"({steps[k].name}): {sim.reason}")
        state = sim.state
    return Commitment(count, finished, state)


def forecast(
    task: Task,
    steps: Sequence[ScheduledAction],
    statuses: Mapping[int, str],
    *,
    min_commit_steps: int = 1,
    horizon: int = 0,
) -> Forecast:
    """Simulate the plan's unfinished steps from the current beliefs (`task`'s initial
    state) and classify: fails in the committed part, fails after it, or holds.

    `horizon` > 0 simulates only that many steps after the committed ones.
    """
    done = commit(task, steps, statuses, min_commit_steps)
    if done.state is None:
        return Forecast(COMMITTED_FAILS, None, done.reason, done)
    rest = steps[done.count :]
    if horizon > 0:
        rest = rest[:horizon]
    if not rest:
        return Forecast(HOLDS, None, "", done)
    origin = rest[0].time
    shifted = tuple(ScheduledAction(a.time - origin, a.name, a.duration) for a in rest)
    sim = simulate(task, Plan(shifted), done.state)
    if sim.ok:
        return Forecast(HOLDS, None, "", done)
    assert sim.failed is not None
    return Forecast(FAILS_LATER, done.count + sim.failed, sim.reason, done)
