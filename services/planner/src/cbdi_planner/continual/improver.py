"""Alg. 2's improving search, in rounds: the offline planner's anytime search, resumable.

Once the executing plan is complete and its forecast holds, the planner looks for a
shorter plan from the committed state (lines 23-24). Searching again the way the first
plan was found finds that plan again; so the improver runs what makes the offline
planner good, from the committed state and below the current plan's makespan:

1. the first plan of the offline planner (the goal agenda, climbing, best-first);
2. after an agenda's plan, climbing to the whole goal at once;
3. greedy best-first search below the best makespan, again while it finds plans;
4. anytime weighted A* with branch and bound.

Each better plan is an `ImprovedPlan` event. The search runs on a worker thread that may
only expand as many nodes as the rounds grant it: a round grants `bound.expansions`
(or `bound.seconds`) and returns once the worker has used them or stopped, so which
plans a round yields depends on the expansions alone, never on thread timing.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from cbdi_planner.best_first import best_first, improving
from cbdi_planner.compression import needs_concurrency
from cbdi_planner.continual.rounds import RoundBound
from cbdi_planner.continual.thread import Event, ImprovedPlan, RoundDone
from cbdi_planner.errors import SearchTimeout
from cbdi_planner.expansion import Expander, Node
from cbdi_planner.hill_climbing import enforced_hill_climbing
from cbdi_planner.plan import plan_from_timeline
from cbdi_planner.search import (
    IMPROVE_LIMIT,
    WEIGHTS,
    Budget,
    SearchStats,
    _Clock,
    _first_plan,
)
from cbdi_planner.state import State
from cbdi_planner.task import Task

__all__ = ["Improver"]

IMPROVE = "improve"  # the mode a round reports


class _Stopped(Exception):
    """The improver was closed: the worker unwinds."""


class _Credits(_Clock):
    """A clock that lets the worker expand only as many nodes as it was granted."""

    def __init__(self, stats: SearchStats) -> None:
        super().__init__(Budget(), time.monotonic, stats)
        self.cond = threading.Condition()
        self.credits = 0
        self.waiting = False  # the worker waits for credits
        self.stopped = False

    def tick(self) -> None:
        with self.cond:
            while self.credits <= 0:
                if self.stopped:
                    raise _Stopped
                self.waiting = True
                self.cond.notify_all()
                self.cond.wait()
            self.waiting = False
            self.credits -= 1
            self.stats.expanded += 1


@dataclass
class Improver:
    """Search for plans shorter than `improve_on` from a committed state, in rounds.

    The same interface as `SearchThread` for the continual planner: `step` runs one
    round, `finished` says the search is over (its space done, or `budget` expansions
    spent), `prefix` counts committed actions.
    """

    task: Task
    state: State
    prefix: int = 0
    improve_on: float = math.inf
    budget: int = 0  # expansions in all at most (0: none)
    epsilon: float = 0.001
    now: Callable[[], float] = time.monotonic
    rounds: int = 0
    finished: bool = False
    found: list[ImprovedPlan] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.stats = SearchStats()
        self.clock = _Credits(self.stats)
        self.best = self.improve_on
        self.error: BaseException | None = None
        self.worker = threading.Thread(target=self._run, name="improver", daemon=True)
        self.started = False

    # -- the worker --------------------------------------------------------------------
    def _run(self) -> None:
        try:
            self._search()
        except (_Stopped, SearchTimeout):
            pass
        except BaseException as exc:  # reported by the next round
            self.error = exc
        finally:
            with self.clock.cond:
                self.clock.stopped = True
                self.clock.waiting = False
                self.clock.cond.notify_all()

    def _search(self) -> None:
        compress = not self.state.open and not needs_concurrency(self.task)
        ex = Expander(self.task, self.epsilon, compress=compress)
        root = ex.root(self.state)
        if ex.dead(root):
            return
        first = _first_plan(ex, root, self.clock, "auto", self.stats)
        if first is not None:
            self._offer(first)
        if self.stats.strategy == "goals":
            whole = enforced_hill_climbing(ex, root, self.clock)
            if whole is not None:
                self._offer(whole)
        while math.isfinite(self.best) and (
            goal := best_first(ex, root, self.clock, self.best, IMPROVE_LIMIT)
        ):
            if not self._offer(goal):
                break
        bound = self.best if math.isfinite(self.best) else math.inf
        for goal in improving(ex, root, self.clock, bound, WEIGHTS):
            self._offer(goal)

    def _offer(self, node: Node) -> bool:
        """Keep `node`'s plan if it is shorter than the best so far."""
        plan = plan_from_timeline(self.task, node.timeline)
        if plan.makespan >= self.best - 1e-9:
            return False
        with self.clock.cond:
            self.found.append(ImprovedPlan(plan, self.best))
            self.best = plan.makespan
        return True

    # -- rounds ------------------------------------------------------------------------
    def step(self, bound: RoundBound, committed: int | None = None) -> list[Event]:
        """Grant the worker one round of expansions; return the plans it found."""
        if self.finished:
            return []
        started = self.now()
        before = self.stats.expanded
        grant = bound.expansions if bound.expansions else 200
        if self.budget:
            grant = min(grant, self.budget - self.stats.expanded)
            if grant <= 0:
                self.close()
                return []
        cond = self.clock.cond
        with cond:
            if not self.started:
                self.started = True
                self.worker.start()
            self.clock.credits += grant
            cond.notify_all()
            while not self.clock.stopped and not (self.clock.waiting and self.clock.credits <= 0):
                cond.wait()
            found, self.found = self.found, []
            over = self.clock.stopped
        self.rounds += 1
        expanded = self.stats.expanded - before
        kind = "goal" if found else "best"
        events: list[Event] = [
            RoundDone(self.rounds, kind, IMPROVE, expanded, self.now() - started, 0, 0)
        ]
        events += found
        if over:
            self.finished = True
            self.worker.join(timeout=5.0)
            if self.error is not None:
                raise self.error
        return events

    def close(self) -> None:
        """Stop the worker (the search was replaced or cancelled)."""
        with self.clock.cond:
            self.clock.stopped = True
            self.clock.cond.notify_all()
        self.finished = True
