"""Forward search over snap (or whole, compressed) actions.

`auto` first reaches the goal facts one at a time (a goal agenda, nearest first, each
stage by enforced hill-climbing); if a stage gets stuck, `ff` follows: enforced
hill-climbing with helpful actions for the whole goal (fast, incomplete), falling back
to complete lazy best-first search, as FF and JavaFF do. `ehc` and `bfs` run one of
them alone. The anytime mode then keeps searching for plans with a shorter makespan:
after an agenda's plan, climbing to the whole goal; then weighted A* on makespan with
branch-and-bound pruning. The searches themselves are `hill_climbing`'s (enforced
hill-climbing, the goal agenda) and `best_first`'s (greedy, anytime weighted A*); this
module runs them within a budget.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

from cbdi_planner.best_first import best_first, improving
from cbdi_planner.compression import needs_concurrency
from cbdi_planner.errors import SearchTimeout
from cbdi_planner.expansion import Expander, Node
from cbdi_planner.hill_climbing import enforced_hill_climbing, goal_agenda
from cbdi_planner.plan import Plan, plan_from_timeline
from cbdi_planner.state import State, initial_state
from cbdi_planner.task import Task

__all__ = ["Budget", "SearchResult", "SearchStats", "search"]

STRATEGIES = ("auto", "ff", "ehc", "bfs")


@dataclass(frozen=True, slots=True)
class Budget:
    """Limits of one search: node expansions and/or seconds (None: unlimited)."""

    max_expansions: int | None = None
    max_seconds: float | None = None
    # Called with the expansion count before each expansion (it may block the search, or
    # raise SearchTimeout to stop it): virtual time paces an offline search epoch by epoch.
    pace: Callable[[int], None] | None = None


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
    compressed: bool = False


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
        if self.budget.pace is not None:
            self.budget.pace(self.stats.expanded)
        limit = self.budget.max_expansions
        if limit is not None and self.stats.expanded > limit:
            raise SearchTimeout(f"expansion budget of {limit} exhausted")
        seconds = self.budget.max_seconds
        if seconds is not None and self.now() - self.started > seconds:
            raise SearchTimeout(f"time budget of {seconds} s exhausted")

    def allowance(self) -> tuple[bool, int | None]:
        """Return whether a compiled loop may count the expansions itself (this clock
        only counts them), and how many more it may make (None: unlimited)."""
        native = (
            type(self).tick is _Clock.tick
            and self.budget.pace is None
            and self.budget.max_seconds is None
        )
        limit = self.budget.max_expansions
        return native, None if limit is None or not native else limit - self.stats.expanded

    def counted(self, expansions: int, ran_out: bool) -> None:
        """Count expansions a compiled loop made; SearchTimeout if its allowance ran out."""
        self.stats.expanded += expansions
        if ran_out:
            raise SearchTimeout(f"expansion budget of {self.budget.max_expansions} exhausted")

    def elapsed(self) -> float:
        return self.now() - self.started


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
    compress: bool | None = None,
) -> SearchResult:
    """Search for a plan from `state` (default: the initial state) within `budget`.

    `compress` searches whole actions (start and end at once, `compression`); None
    (default) does so when the task needs no concurrency, and falls back to snap
    actions if the compressed space turns out to hold no plan.
    """
    if strategy not in STRATEGIES:
        raise ValueError(f"unknown search strategy {strategy!r}; use one of {STRATEGIES}")
    stats = SearchStats(strategy=strategy)
    clock = _Clock(budget or Budget(), now, stats)
    stats.compressed = not needs_concurrency(task) if compress is None else compress
    ex = Expander(task, epsilon, compress=stats.compressed)
    result = SearchResult("timeout", None, stats)
    counted: list[Expander] = [ex]
    try:
        root = ex.root(state or initial_state(task))
        goal = _first_plan(ex, root, clock, strategy, stats) if not ex.dead(root) else None
        if goal is None and stats.compressed and compress is None:
            # The compressed space has no plan: one may need overlapping actions.
            ex = Expander(task, epsilon)
            counted.append(ex)
            root = ex.root(state or initial_state(task))
            stats.compressed = False
            goal = _first_plan(ex, root, clock, strategy, stats)
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
    stats.generated = sum(e.generated for e in counted)
    stats.evaluated = sum(e.evaluated for e in counted)
    stats.inconsistent = sum(e.inconsistent for e in counted)
    stats.seconds = clock.elapsed()
    return result


def _first_plan(
    ex: Expander, root: Node, clock: _Clock, strategy: str, stats: SearchStats
) -> Node | None:
    if strategy == "auto":
        goal = goal_agenda(ex, root, clock)
        if goal is not None:
            stats.strategy = "goals"
            return goal
    if strategy in ("ehc", "ff", "auto"):
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
    """Search for plans shorter than the best so far until the budget runs out."""
    assert result.plan is not None
    if result.stats.strategy == "goals":
        # The agenda is fast but myopic: climbing to the whole goal at once often
        # finds a much shorter plan, a good bound for what follows.
        goal = enforced_hill_climbing(ex, root, clock)
        if goal is not None:
            _record(ex.task, goal, result, clock, on_plan)
    # Greedy best-first search below the best makespan so far, again and again while
    # it finds plans within its expansion limit: climbing's first plans can be long,
    # and this finds a much shorter one fast on many tasks (driverlog p08: 211 -> 101).
    while (goal := best_first(ex, root, clock, result.plan.makespan, IMPROVE_LIMIT)) is not None:
        _record(ex.task, goal, result, clock, on_plan)
    for goal in improving(ex, root, clock, result.plan.makespan, WEIGHTS):
        _record(ex.task, goal, result, clock, on_plan)


WEIGHTS = (2.0, 1.0)
IMPROVE_LIMIT = 5000  # expansions of one bounded greedy search for a shorter plan
