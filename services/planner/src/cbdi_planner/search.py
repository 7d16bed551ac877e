"""Forward search over snap actions: enforced hill-climbing and greedy best-first search.

`auto` runs enforced hill-climbing with helpful actions first (fast, incomplete) and
falls back to complete best-first search if it gets stuck, as FF and JavaFF do. The
anytime mode then keeps searching for plans with a shorter makespan.
"""

from __future__ import annotations

import heapq
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

from cbdi_planner.errors import SearchTimeout
from cbdi_planner.expansion import Expander, Node
from cbdi_planner.plan import Plan, plan_from_timeline
from cbdi_planner.state import State, initial_state, is_goal
from cbdi_planner.task import Task

__all__ = ["Budget", "SearchResult", "SearchStats", "search"]

STRATEGIES = ("ehc", "bfs", "auto")


@dataclass(frozen=True, slots=True)
class Budget:
    """Limits of one search: node expansions and/or seconds (None: unlimited)."""

    max_expansions: int | None = None
    max_seconds: float | None = None


@dataclass(slots=True)
class SearchStats:
    """What a search did, for logs, the CLI and the benchmark."""

    expanded: int = 0
    generated: int = 0
    evaluated: int = 0
    inconsistent: int = 0
    seconds: float = 0.0
    strategy: str = ""
    plans: int = 0


@dataclass(slots=True)
class SearchResult:
    """The outcome: `status` is `solved`, `unsolvable`, `timeout` or `incomplete`.

    `incomplete` means enforced hill-climbing alone got stuck (no proof of anything).
    `improvements` lists `(seconds, makespan)` for each better plan found.
    """

    status: str
    plan: Plan | None
    stats: SearchStats
    improvements: list[tuple[float, float]] = field(default_factory=list)


class _Clock:
    """Enforce a budget; `now` is injected so tests never depend on wall time."""

    def __init__(self, budget: Budget, now: Callable[[], float], stats: SearchStats) -> None:
        self.budget, self.now, self.stats = budget, now, stats
        self.started = now()

    def tick(self) -> None:
        self.stats.expanded += 1
        limit = self.budget.max_expansions
        if limit is not None and self.stats.expanded > limit:
            raise SearchTimeout(f"expansion budget of {limit} exhausted")
        seconds = self.budget.max_seconds
        if seconds is not None and self.now() - self.started > seconds:
            raise SearchTimeout(f"time budget of {seconds} s exhausted")

    def elapsed(self) -> float:
        return self.now() - self.started


def enforced_hill_climbing(ex: Expander, root: Node, clock: _Clock) -> Node | None:
    """Climb to strictly better heuristic values by breadth-first search on helpful actions.

    Return a goal node, or None when a plateau cannot be escaped (the caller may fall
    back to best-first search).
    """
    current = root
    seen = {root.state.key()}
    while not is_goal(ex.task, current.state):
        queue, better = deque([current]), None
        while queue and better is None:
            node = queue.popleft()
            clock.tick()
            for state, timeline, running in ex.successors(node, helpful_only=True):
                if state.key() in seen:
                    continue
                seen.add(state.key())
                child = ex.evaluate(state, timeline, running)
                if ex.dead(child):
                    continue
                if is_goal(ex.task, state):
                    return child
                if child.h < current.h:
                    better = child
                    break
                queue.append(child)
        if better is None:
            return None
        current = better
    return current


def best_first(ex: Expander, root: Node, clock: _Clock, bound: float | None = None) -> Node | None:
    """Run greedy best-first search on h (ties: fewer steps); None if exhausted.

    With `bound`, nodes whose partial plan already reaches that makespan are pruned,
    which turns the search into the improving phase of the anytime mode.
    """
    if is_goal(ex.task, root.state):
        return root
    counter = 0
    frontier = [(root.h, 0, counter, root)]
    best_span: dict[object, float] = {root.state.key(): 0.0}
    while frontier:
        _, _, _, node = heapq.heappop(frontier)
        clock.tick()
        for state, timeline, running in ex.successors(node):
            span = timeline.makespan
            if bound is not None and span >= bound - 1e-9:
                continue
            key = state.key()
            known = best_span.get(key)
            if known is not None and (bound is None or known <= span + 1e-9):
                continue
            best_span[key] = span
            child = ex.evaluate(state, timeline, running)
            if ex.dead(child):
                continue
            if is_goal(ex.task, state):
                return child
            counter += 1
            heapq.heappush(frontier, (child.h, len(timeline.steps), counter, child))
    return None


def search(
    task: Task,
    *,
    strategy: str = "auto",
    budget: Budget | None = None,
    epsilon: float = 0.001,
    anytime: bool = False,
    state: State | None = None,
    on_plan: Callable[[Plan], None] | None = None,
    now: Callable[[], float] = time.monotonic,
) -> SearchResult:
    """Search for a plan from `state` (default: the initial state) within `budget`."""
    if strategy not in STRATEGIES:
        raise ValueError(f"unknown search strategy {strategy!r}; use one of {STRATEGIES}")
    stats = SearchStats(strategy=strategy)
    clock = _Clock(budget or Budget(), now, stats)
    ex = Expander(task, epsilon)
    result = SearchResult("timeout", None, stats)
    try:
        root = ex.root(state or initial_state(task))
        goal = _first_plan(ex, root, clock, strategy, stats) if not ex.dead(root) else None
        if goal is None:
            result.status = "incomplete" if stats.strategy == "ehc" else "unsolvable"
        else:
            _record(task, goal, result, clock, on_plan)
            result.status = "solved"
            if anytime:
                _improve(ex, root, clock, result, on_plan)
    except SearchTimeout:
        # The budget ran out: "timeout" unless a plan was found (anytime: the best so far).
        result.status = "solved" if result.plan is not None else "timeout"
    stats.generated, stats.evaluated = ex.generated, ex.evaluated
    stats.inconsistent = ex.inconsistent
    stats.seconds = clock.elapsed()
    return result


def _first_plan(
    ex: Expander, root: Node, clock: _Clock, strategy: str, stats: SearchStats
) -> Node | None:
    if strategy in ("ehc", "auto"):
        goal = enforced_hill_climbing(ex, root, clock)
        if goal is not None or strategy == "ehc":
            stats.strategy = "ehc"
            return goal
    stats.strategy = "bfs" if strategy == "bfs" else "ehc+bfs"
    return best_first(ex, root, clock)


def _record(
    task: Task,
    goal: Node,
    result: SearchResult,
    clock: _Clock,
    on_plan: Callable[[Plan], None] | None,
) -> bool:
    plan = plan_from_timeline(task, goal.timeline)
    if result.plan is not None and plan.makespan >= result.plan.makespan - 1e-9:
        return False
    result.plan = plan
    result.stats.plans += 1
    result.improvements.append((clock.elapsed(), plan.makespan))
    if on_plan is not None:
        on_plan(plan)
    return True


def _improve(
    ex: Expander,
    root: Node,
    clock: _Clock,
    result: SearchResult,
    on_plan: Callable[[Plan], None] | None,
) -> None:
    """Search again and again, each time only for plans shorter than the best so far."""
    while result.plan is not None:
        goal = best_first(ex, root, clock, bound=result.plan.makespan)
        if goal is None or not _record(ex.task, goal, result, clock, on_plan):
            return
