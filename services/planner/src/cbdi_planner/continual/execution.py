"""The execution simulator and the failure forecast (the paper's Section III-C).

From the executing plan and each step's status, `commit` finds the committed actions
(every step that started, then more until at least `min_commit_steps` not yet finished
are committed) and the committed state: the current beliefs with the committed actions
simulated on them. `forecast` simulates the rest of the plan from there (or only its next
`horizon` actions, the paper's proposed refinement) and classifies the outcome.

A started step's effects are applied once: the beliefs may show some already, since the
step's status (from the executor) can come after the percepts that show its start or even
its end. Given when the beliefs were sensed and when each step began (`Sensed`), a
started step whose start lies before the beliefs and whose start effects on facts all
show in them (but those its end undoes: a drive takes `idle` and gives it back) has its
start counted as shown, and one whose planned end also lies at or
before the beliefs and whose end effects on facts all show has ended in them; a shown
part's numeric effects (an `increase`, a `decrease`) are not applied again. Effects on
facts are evidence; a part with none is judged by the time alone (an action stretched
past its planned end then counts as ended early: its numeric end effect is missed, not
doubled). A started step that no longer grounds from the beliefs (what it needed is gone,
as an item it picked up) has ended in them once its planned end lies before them. Without
`Sensed` every started step is applied whole, as before.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from cbdi_planner.plan import Plan, ScheduledAction
from cbdi_planner.simulate import simulate
from cbdi_planner.state import State
from cbdi_planner.task import GroundAction, Snap, Task, holds

__all__ = [
    "COMMITTED_FAILS",
    "FAILS_LATER",
    "HOLDS",
    "Commitment",
    "Forecast",
    "Sensed",
    "commit",
    "forecast",
]

COMMITTED_FAILS = "fails_in_committed"  # nothing to do: execution will report it
FAILS_LATER = "fails_after_committed"  # search again from the committed state
HOLDS = "holds"  # start the improver

DONE = ("succeeded",)
STARTED = ("running", "succeeded")
EPS = 1e-6  # simulated seconds: times this close are the same time


@dataclass(frozen=True, slots=True)
class Sensed:
    """When the beliefs were sensed (`now`) and when each started step began (its index
    in the plan -> the world's start time, from the executor's `running` status)."""

    now: float
    began: Mapping[int, float]


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


def _force(
    task: Task, state: State, step: ScheduledAction, began: float | None, now: float | None
) -> State | None:
    """Apply an already started action's effects (the world decided it could start; the
    beliefs may already show part of its effects: `_shown`); None if no copy of it fits.

    A name split into copies, one per disjunct of its conditions, means the copy that
    applies in `state`: its start condition holds and, for a durative one, its invariant
    and end condition hold after its start effects (which copy's effects happen depends
    on what held at its start). Failing that, the copy whose start condition holds but
    for the facts its start changes (beliefs that already show them). A lone copy is
    forced unchecked.
    """
    copies = [a for a in task.actions if a.name == step.name and not a.internal]
    if len(copies) > 1:
        copies = [a for a in copies if _fits(a, state, False)] or [
            a for a in copies if _fits(a, state, True)
        ]
    if not copies:
        # Nothing of it grounds from these beliefs (what it needed is gone: an item it
        # picked up): past its planned end it ended in them, else it cannot be simulated.
        over = began is not None and now is not None and now >= began + (step.duration or 0.0)
        return state if over else None
    action = copies[0]
    start, end = _shown(action, state.facts, step.duration or 0.0, began, now)
    if end:
        return state  # it ended in the beliefs: all of it shows
    if start:  # its facts again (no change), its numbers not
        facts, nums = (state.facts & ~action.start.dele) | action.start.add, state.nums
    else:
        facts, nums = action.start.apply(state.facts, state.nums)
    if action.end is not None:
        facts, nums = action.end.apply(facts, nums)
    return State(facts, nums, state.open, state.til)


def _shown(
    action: GroundAction, facts: int, duration: float, began: float | None, now: float | None
) -> tuple[bool, bool]:
    """Whether beliefs sensed at `now` (`facts`) show the start and the end of `action`,
    which began at `began` (unknown: None, neither shows)."""
    if began is None or now is None or now <= began + EPS:
        return False, False
    if action.end is None:
        start = _shows(action.start, facts)
        return start, start
    # What the end undoes of the start tells nothing of the start: a drive's start
    # takes `idle` and its end gives it back, so an ended drive shows `idle` as if it
    # never started (its charge would be used twice).
    start = _shows(action.start, facts, action.end.add | action.end.dele)
    if not start or not _shows(action.end, facts):
        return start, False
    # Past its planned end, or ended early (a performer faster than planned): its end's
    # effects on facts show; an end with none is judged by the time alone.
    has_facts = bool(action.end.add | action.end.dele)
    return start, has_facts or now >= began + duration - EPS


def _shows(snap: Snap, facts: int, undone: int = 0) -> bool:
    """Whether `facts` show a happening's unconditional effects on facts, but those on
    the facts `undone` (True if it has none: then only the time tells)."""
    add, dele = snap.add & ~undone, snap.dele & ~snap.add & ~undone
    return (add & ~facts) == 0 and (dele & facts) == 0


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
    sensed: Sensed | None = None,
    start: State | None = None,
) -> Commitment:
    """Return the commitment of the plan `steps` (in order) given each step's status.

    `task`'s initial state is the current beliefs, which include every finished step
    (and, told by `sensed`, what of the started ones they show). `start`: the state to
    simulate from instead (a plan that follows the running steps of another plan: the
    state they leave).
    """
    finished = 0
    while finished < len(steps) and statuses.get(finished) in DONE:
        finished += 1
    count = finished
    while count < len(steps) and statuses.get(count) in STARTED:
        count += 1
    count = min(len(steps), max(count, finished + min_commit_steps))
    state = start or State(task.init_facts, task.init_nums)
    for k in range(finished, count):
        if statuses.get(k) in STARTED:
            began = sensed.began.get(k) if sensed is not None else None
            now = sensed.now if sensed is not None else None
            forced = _force(task, state, steps[k], began, now)
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
    sensed: Sensed | None = None,
    start: State | None = None,
) -> Forecast:
    """Simulate the plan's unfinished steps from the current beliefs (`task`'s initial
    state) and classify: fails in the committed part, fails after it, or holds.

    `horizon` > 0 simulates only that many steps after the committed ones; `sensed` and
    `start` as for `commit`.
    """
    done = commit(task, steps, statuses, min_commit_steps, sensed, start)
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
