"""searchThread (the paper's Algorithm 2): rounds of search that hand out partial plans.

`SearchThread` is a deterministic state machine: each `step()` runs one round
(Alg. 2 line 6) and returns what the loop body decides, as `Event`s for the service to
send: a partial plan with its baseline (lines 15-17), the fall-back from greedy to
complete search (lines 10-14), the search failing (line 22), the search becoming
outdated (line 9) or, in improving mode, an improved plan (lines 23-24).

Plans are segments of one timeline whose times count from the search's origin (the
committed state); `PartialPlanFound.plan` holds the segment's actions with those times.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

from cbdi_planner.continual.rounds import NG, G, Round, RoundBound, SearchSpace
from cbdi_planner.expansion import Node
from cbdi_planner.plan import Plan, ScheduledAction
from cbdi_planner.state import State, is_goal
from cbdi_planner.stn import END, INST, START
from cbdi_planner.task import Task

__all__ = [
    "Event",
    "ImprovedPlan",
    "ModeChanged",
    "Outdated",
    "PartialPlanFound",
    "RoundDone",
    "SearchFailed",
    "SearchThread",
    "segment",
]

UNSAT = "UNSAT"


@dataclass(frozen=True, slots=True)
class PartialPlanFound:
    """Alg. 2 line 17: a new partial plan continuing `baseline` (the number of partial
    plans sent before it in this search); `complete` when it reaches the goal."""

    plan: Plan
    baseline: int
    complete: bool


@dataclass(frozen=True, slots=True)
class ModeChanged:
    """Alg. 2 lines 10-14: the greedy search failed; the complete one restarts."""

    mode: str


@dataclass(frozen=True, slots=True)
class SearchFailed:
    """Alg. 2 line 22: no plan (the complete search exhausted its space, or gave up).

    `proved`: the search never re-rooted, so there is no plan from its origin. One that
    re-rooted on its partial plans searched only what lies after them: they may have led
    where the goal is out of reach (a battery spent far from the dock), and a search of
    the whole space from the origin (`SearchThread.whole`) may still find a plan.
    """

    reason: str
    proved: bool = True


@dataclass(frozen=True, slots=True)
class Outdated:
    """Alg. 2 line 9: execution committed past this search's prefix."""


@dataclass(frozen=True, slots=True)
class ImprovedPlan:
    """Alg. 2 lines 23-24: a complete plan with a shorter makespan than `than`."""

    plan: Plan
    than: float


@dataclass(frozen=True, slots=True)
class RoundDone:
    """Statistics of one round (for the service's per-round status)."""

    number: int
    kind: str
    mode: str
    expanded: int
    seconds: float
    best_h: int
    plan_actions: int


Event = PartialPlanFound | ModeChanged | SearchFailed | Outdated | ImprovedPlan | RoundDone


def segment(task: Task, node: Node, first: int) -> Plan:
    """Return the actions started in `node`'s timeline from step `first` on, leaving out
    the planner's internal actions (those of a disjunctive goal), as `plan_from_timeline`.

    Every action started in the segment ends in it when `node` has no running action.
    """
    tl = node.timeline
    steps, actions = tl.steps, task.actions
    times = tl.times  # read once (a copy, on the compiled core)
    # the end of a start from `first` on comes after it: the steps before need no look
    ends = {steps[k].partner: k for k in range(first, len(steps)) if steps[k].kind == END}
    out = []
    for k in _plan_steps(task, node, first):
        step = steps[k]
        when = round(times[k], 6)
        name = actions[step.action].name
        if step.kind == INST:
            out.append(ScheduledAction(when, name, None))
        else:
            dur = round(times[ends[k]] - times[k], 6)
            out.append(ScheduledAction(when, name, dur))
    out.sort(key=lambda a: a.time)
    return Plan(tuple(out))


def _plan_steps(task: Task, node: Node, first: int) -> list[int]:
    """Return the indexes of the timeline steps from `first` on that start a plan action
    (ends go with their starts; internal actions are no plan's)."""
    steps = node.timeline.steps
    return [
        k
        for k in range(first, len(steps))
        if steps[k].kind in (START, INST) and not task.actions[steps[k].action].internal
    ]


@dataclass
class SearchThread:
    """The continual search from a committed state (`prefix`: committed actions' count).

    `improving` searches for a plan better than `improve_on` (a makespan) instead of
    handing out partial plans. `empty_rounds` rounds without progress end the search.
    `whole` (complete search only) hands out no partial plan, only the plan that reaches
    the goal: it never re-roots, so its exhausted space proves there is no plan.
    """

    task: Task
    state: State
    prefix: int = 0
    improving: bool = False
    improve_on: float = float("inf")
    empty_rounds: int = 10
    epsilon: float = 0.001
    now: Callable[[], float] = time.monotonic
    agenda: bool = False  # the greedy search reaches the goal facts one at a time
    mode: str = G
    whole: bool = False
    sent: int = 0
    rerooted: bool = False
    rounds: int = 0
    empty: int = 0
    finished: bool = False
    plans: list[Plan] = field(default_factory=list)

    def __post_init__(self) -> None:
        if self.whole and self.mode != NG:
            raise ValueError("only the complete search (NG) searches the whole space")
        self.space = SearchSpace(
            self.task,
            self.state,
            mode=self.mode,
            epsilon=self.epsilon,
            now=self.now,
            agenda=self.agenda,
        )
        self.origin = self.space.root

    def step(self, bound: RoundBound, committed: int | None = None) -> list[Event]:
        """Run one round; `committed` is the number of committed actions now (lines 7-8)."""
        if self.finished:
            return []
        if is_goal(self.task, self.space.root.state):  # line 5
            self.finished = True
            return []
        if self.whole:  # no partial plan: rounds end by time or expansions alone
            bound = RoundBound(bound.seconds, bound.expansions, None)
        found = self.space.search_round(bound)  # line 6
        self.rounds += 1
        events: list[Event] = [self._stats(found)]
        if committed is not None and committed > self.prefix:  # line 9
            self.finished = True
            return [*events, Outdated()]
        if found.kind == "exhausted":  # lines 10-14
            return events + self._fall_back("the search space is exhausted")
        node = found.node
        assert node is not None
        if self.whole and found.kind != "goal":
            return events  # the best state so far is no plan to commit to
        if node is self.space.root:  # no progress this round
            self.empty += 1
            if self.mode == G and self.empty >= self.empty_rounds:
                # Greedy search on a plateau: the complete search takes over (only an
                # exhausted complete search proves there is no plan).
                return events + self._fall_back(f"{self.empty} rounds without progress")
            return events
        self.empty = 0
        return events + self._progress(node, found.kind == "goal")

    def _progress(self, node: Node, goal: bool) -> list[Event]:
        """Lines 15-20: send the new partial plan (unless improving), re-root on it."""
        plan = segment(self.task, node, self.space.root_steps)
        events: list[Event] = []
        self.plans.append(plan)
        if not self.improving:
            events.append(PartialPlanFound(plan, self.sent, goal))  # line 17
            self.sent += 1
        if goal:
            self.finished = True
            whole = segment(self.task, node, 0)
            if self.improving and whole.makespan < self.improve_on - 1e-9:  # lines 23-24
                events.append(ImprovedPlan(whole, self.improve_on))
            return events
        self.space.reroot(node)  # line 19
        self.rerooted = True
        return events

    def _fall_back(self, why: str) -> list[Event]:
        """Lines 11-14 and 21-22: G falls back to NG from the origin; NG fails."""
        if self.mode == G:
            self.mode = NG
            self.empty = 0
            # Partial plans already out stay: the complete search continues after them;
            # otherwise it starts over from the committed state (lines 13-14).
            self.space.restart(NG, self.space.root if self.sent else self.origin)
            return [ModeChanged(NG)]
        self.mode = UNSAT
        self.finished = True
        if self.improving:
            return []
        return [SearchFailed(f"no plan: {why} (complete search)", proved=not self.rerooted)]

    def _stats(self, found: Round) -> RoundDone:
        size = 0
        if found.node is not None:
            size = len(_plan_steps(self.task, found.node, self.space.root_steps))
        return RoundDone(
            self.rounds, found.kind, self.mode, found.expanded, found.seconds, found.best_h, size
        )
