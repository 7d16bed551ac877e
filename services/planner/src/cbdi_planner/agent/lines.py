"""The online planner's lines and searches, and the messages they turn into (pure).

A *line* is one plan as the executor sees it (one plan id): its partial plans continue
it (baseline: the plan id). A repair, a revised goal or an improvement starts a new line
from the committed state (baseline and `applies_after`: the last committed step), which
the scheduler swaps in with an early arrest. A *search* is a search thread and the line
it fills (`ContinualPlanner` in `cbdi_planner.agent.continual` keeps both), searched
for a `Purpose`.

A new line follows steps of the lines before it, which may still run while its own
wait (a robot mid-drive); so may the line after it, before either starts. The planner
keeps those lines: what they leave (`followed`) is where the new line's steps start,
and a new search follows their running steps (`running_line`, `held`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from enum import StrEnum

from msgspec.structs import replace

from cbdi.wire.agent import PartialPlan
from cbdi.wire.planner import ForecastReport, SearchRound, SearchStatus
from cbdi_planner.agent.steps import held_at_start, plan_steps
from cbdi_planner.continual import Forecast, RoundDone, SearchThread, Sensed, commit
from cbdi_planner.continual.improver import Improver
from cbdi_planner.pddl.ast import Domain
from cbdi_planner.plan import Plan, ScheduledAction
from cbdi_planner.state import State
from cbdi_planner.task import Task

__all__ = [
    "Line",
    "Purpose",
    "Search",
    "extend",
    "failure_status",
    "followed",
    "forecast_report",
    "held",
    "plan_prefix",
    "round_report",
    "running_line",
    "search_status",
    "sent_own_plan",
]


class Purpose(StrEnum):
    """Why a search runs. The value is the word of the wire and the logs
    (`PartialPlan.purpose`, `SearchRound.purpose`), which recordings and the monitor's
    counts by purpose keep: never rename one.
    """

    NEW = "new"  # a plan for a request, from scratch or after a running step
    REPAIR = "repair"  # the executing plan is forecast to fail: another after its committed part
    REVISE = "revise"  # the goal grew: a plan for the union, after the committed part
    IMPROVE = "improve"  # the executing plan holds: a shorter one after its committed part


@dataclass
class Line:
    """One plan id's published steps (absolute simulated times) and their statuses."""

    plan_id: str
    purpose: Purpose
    origin: float
    baseline: str = ""
    applies_after: str = ""
    steps: list[ScheduledAction] = field(default_factory=list)
    step_ids: list[str] = field(default_factory=list)
    statuses: dict[int, str] = field(default_factory=dict)
    began: dict[int, float] = field(default_factory=dict)  # started steps' start times
    complete: bool = False
    improved: bool = False

    def running(self) -> list[ScheduledAction]:
        """The steps of this line that run now."""
        return [self.steps[k] for k, st in sorted(self.statuses.items()) if st == "running"]

    def makespan_after(self, first: int) -> float:
        """Return the scheduled span of the steps from index `first` on."""
        rest = self.steps[first:]
        if not rest:
            return 0.0
        return max(a.time + (a.duration or 0.0) for a in rest) - rest[0].time


@dataclass
class Search:
    """A search thread and the line it fills (or, improving, may replace)."""

    thread: SearchThread | Improver
    line: Line
    purpose: Purpose
    request_id: str
    repairs: Line | None = None  # the executing line this search continues from
    blocked: bool | None = None  # a failed search: blocked by something that moves?


def held(domain: Domain, lines: Sequence[Line | None]) -> list[tuple[str, ...]]:
    """The facts the running steps of `lines` started from (`held_at_start`): beliefs
    sensed since may lack them, and the committed state needs those steps."""
    return [
        f
        for line in lines
        if line is not None
        for step in line.running()
        for f in held_at_start(domain, step.name)
    ]


def sent_own_plan(search: Search, executing: Line | None) -> bool:
    """Whether `search` is a new plan's that sent partial plans, its line `executing`:
    a search from the committed state may replace them."""
    thread = search.thread
    return (
        isinstance(thread, SearchThread)
        and thread.sent > 0
        and search.line is executing
        and search.purpose == Purpose.NEW
    )


def running_line(lines: Sequence[Line | None]) -> Line | None:
    """The first of `lines` with a step that runs now."""
    return next((line for line in lines if line is not None and line.running()), None)


def followed(task: Task, line: Line, previous: Sequence[Line], now: float) -> State | None:
    """The state the steps that `line` follows (up to its `applies_after`, in the lines
    of `previous`, oldest first) leave when one of them runs; None if none runs (its own
    steps start from the beliefs) or they cannot be simulated. `now`: when the beliefs
    (`task`'s initial state) were sensed."""
    after = line.applies_after
    prev = next((p for p in reversed(previous) if after and after in p.step_ids), None)
    if prev is None or prev is line:
        return None
    start = followed(task, prev, previous, now)  # what `prev` follows in turn
    last = prev.step_ids.index(after) + 1
    statuses = {k: st for k, st in prev.statuses.items() if k < last}
    if start is None and "running" not in statuses.values():
        return None
    sensed = Sensed(now, prev.began)
    return commit(task, prev.steps[:last], statuses, last, sensed, start).state


def plan_prefix(agent: str, life: int) -> str:
    """How the plan ids of `agent`'s planner begin: `robot1-plan-` (then 1, 2, ...), and
    after its first restart `robot1-plan-r1-`, and so on."""
    return f"{agent}-plan-" if life == 0 else f"{agent}-plan-r{life}-"


def extend(
    agent: str,
    domain: Domain,
    search: Search,
    plan: Plan,
    complete: bool,
    on_grid: Callable[[float], float],
) -> PartialPlan:
    """Append `plan` (times from the line's origin) to `search`'s line; return the
    partial plan that tells the executor (step starts on the epoch grid, `on_grid`)."""
    line = search.line
    first = len(line.steps)
    steps = plan_steps(domain, plan, line.origin, line.plan_id)
    out_steps = []
    for k, (scheduled, step) in enumerate(zip(plan.actions, steps, strict=True)):
        start = on_grid(line.origin + scheduled.time)
        step_id = f"{line.plan_id}-{first + k + 1}"
        out_steps.append(replace(step, step_id=step_id, start=start))
        line.steps.append(
            ScheduledAction(line.origin + scheduled.time, scheduled.name, scheduled.duration)
        )
        line.step_ids.append(step_id)
    line.complete = complete
    return PartialPlan(
        agent=agent,
        plan_id=line.plan_id,
        baseline=line.baseline if first == 0 else line.plan_id,
        steps=out_steps,
        complete=complete,
        applies_after=line.applies_after if first == 0 else "",
        request_id=search.request_id,
        purpose=search.purpose.value,
    )


def round_report(agent: str, search: Search, r: RoundDone, now: float) -> SearchRound:
    """A round of `search`, as the planner reports it."""
    return SearchRound(
        agent=agent,
        request_id=search.request_id,
        plan_id=search.line.plan_id,
        purpose=search.purpose.value,
        number=r.number,
        kind=r.kind,
        mode=r.mode,
        expanded=r.expanded,
        seconds=r.seconds,
        best_h=r.best_h if r.best_h < 10**9 else -1,
        plan_actions=r.plan_actions,
        time=now,
    )


def forecast_report(agent: str, line: Line, fc: Forecast, now: float) -> ForecastReport:
    """The forecast `fc` of `line`'s plan, as the planner reports it."""
    failed = line.step_ids[fc.failed] if fc.failed is not None else ""
    done = fc.commitment.count
    return ForecastReport(
        agent=agent,
        plan_id=line.plan_id,
        kind=fc.kind,
        failed_step=failed,
        reason=fc.reason,
        committed=line.step_ids[done - 1] if done else "",
        time=now,
    )


def search_status(agent: str, request_id: str, status: str, reason: str = "") -> SearchStatus:
    """A search request's status."""
    return SearchStatus(agent=agent, request_id=request_id, status=status, reason=reason)


def failure_status(agent: str, request_id: str, reason: str, blocked: bool) -> SearchStatus:
    """A failed search, `blocked` if the goal is reachable once moving things move."""
    if blocked:
        reason += " (blocked by something that moves: waiting for it)"
    return SearchStatus(
        agent=agent, request_id=request_id, status="failed", reason=reason, blocked=blocked
    )
