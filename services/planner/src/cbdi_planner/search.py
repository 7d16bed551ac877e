"""Forward search over snap (or whole, compressed) actions.

`auto` first reaches the goal facts one at a time (a goal agenda, nearest first, each
stage by enforced hill-climbing); if a stage gets stuck, `ff` follows: enforced
hill-climbing with helpful actions for the whole goal (fast, incomplete), falling back
to complete lazy best-first search, as FF and JavaFF do. `ehc` and `bfs` run one of
them alone. The anytime mode then keeps searching for plans with a shorter makespan:
after an agenda's plan, climbing to the whole goal; then weighted A* on makespan with
branch-and-bound pruning.
"""

from __future__ import annotations

import heapq
import math
import time
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

from cbdi_planner import loops
from cbdi_planner.compression import needs_concurrency
from cbdi_planner.errors import SearchTimeout
from cbdi_planner.expansion import Expander, Move, Node
from cbdi_planner.plan import Plan, plan_from_timeline
from cbdi_planner.state import State, initial_state, is_goal
from cbdi_planner.stn import END, TIL, Step
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


def enforced_hill_climbing(ex: Expander, root: Node, clock: _Clock) -> Node | None:
    """Climb to strictly better heuristic values by breadth-first search on helpful actions.

    When the helpful actions of a plateau lead nowhere better, the breadth-first search
    is run again on all actions before giving up. States are remembered per climb step
    only (as in FF), so a state passed over on one step may serve a later one. Return a
    goal node, or None when a plateau cannot be escaped (the caller may fall back to
    best-first search).
    """
    if loops.runs(ex, root):
        return loops.hill_climb(ex, root, clock)
    current = root
    while not ex.reached(current.state):
        better = _climb(ex, current, clock, helpful_only=True)
        if better is None:
            better = _climb(ex, current, clock, helpful_only=False)
        if better is None:
            return None
        current = better
    return current


def _climb(ex: Expander, current: Node, clock: _Clock, helpful_only: bool) -> Node | None:
    """Breadth-first search from `current` for a goal or a node with a smaller h.

    Give up after `PLATEAU` expansions: a plateau that wide is best left to best-first
    search, which keeps what it learns.
    """
    seen = {current.state.key()}
    queue = deque([current])
    for _ in range(PLATEAU):
        if not queue:
            break
        node = queue.popleft()
        clock.tick()
        # Shortest partial plans first: of equally good successors, the one that runs
        # in parallel with the plan so far wins.
        successors = sorted(
            ex.successors(node, helpful_only=helpful_only), key=lambda s: s[1].makespan
        )
        for state, timeline, running in successors:
            key = state.key()
            if key in seen:
                continue
            seen.add(key)
            child = ex.evaluate(state, timeline, running)
            if ex.dead(child):
                continue
            if ex.reached(state) or child.h < current.h:
                return child
            queue.append(child)
    return None


def best_first(
    ex: Expander,
    root: Node,
    clock: _Clock,
    bound: float = math.inf,
    limit: int | None = None,
) -> Node | None:
    """Run greedy best-first search on h (ties: fewer steps); None if exhausted.

    Partial plans as long as `bound` are pruned; `limit` caps the expansions (None
    when reached, as when exhausted).

    Evaluation is deferred: a successor waits in the open list with its parent's h and
    is evaluated only when taken out, so the heuristic runs once per expanded node
    rather than once per generated one. Successors reached by a helpful happening also
    go to a second open list, taken in turn with the first and exclusively for a while
    after h improves (Fast Downward's boosted dual queue): helpful actions lead the
    way, the full list keeps the search complete.
    """
    if loops.runs(ex, root):
        return loops.best_first(ex, root, clock, bound, limit)
    lists: tuple[list[_Lazy], list[_Lazy]] = ([(root.h, 0, 0, root, None)], [])
    closed: set[object] = set()
    counter, turn, boost, best_h = 0, 0, 0, root.h
    while lists[0] or lists[1]:
        turn = _next_list(lists, turn, boost)
        boost = max(0, boost - 1)
        node = _take(ex, heapq.heappop(lists[turn]), closed)
        if node is None or node.makespan >= bound - 1e-9:
            continue
        closed.add(node.state.key())
        if ex.reached(node.state):
            return node
        if node.h < best_h:
            best_h, boost = node.h, _BOOST
        if limit is not None:
            if limit <= 0:
                return None
            limit -= 1
        clock.tick()
        steps = len(node.timeline.steps)
        for move in ex.moves(node):
            if move.state.key() in closed:
                continue
            counter += 1
            entry = (node.h, steps + len(move.steps), counter, node, move)
            heapq.heappush(lists[0], entry)
            if _helpful_step(node, move.first):
                heapq.heappush(lists[1], entry)
    return None


# (priority, steps, tie-break, node or parent, move to schedule and evaluate or None)
_Lazy = tuple[float, int, int, Node, Move | None]
_Entry = tuple[float, int, int, Node]
_BOOST = 1000  # expansions on the helpful list alone after h improves


def _take(ex: Expander, entry: _Lazy, closed: set[object]) -> Node | None:
    """Return the node of an open-list entry, scheduling and evaluating it now.

    None: the node is closed, its timeline inconsistent or the heuristic finds it dead.
    """
    parent, move = entry[3], entry[4]
    if move is None:
        return None if parent.state.key() in closed else parent
    if move.state.key() in closed:
        return None
    timeline = ex.schedule(parent.timeline, move)
    if timeline is None:
        return None
    node = ex.evaluate(move.state, timeline, move.running)
    return None if ex.dead(node) else node


def _next_list(lists: tuple[list[_Lazy], list[_Lazy]], turn: int, boost: int) -> int:
    """Alternate between the open lists, staying on the helpful one while boosted."""
    if not lists[1]:
        return 0
    if boost > 0 or not lists[0]:
        return 1
    return turn ^ 1


def _helpful_step(parent: Node, step: Step) -> bool:
    """Tell whether the step that chose a move is helpful in `parent` (ends always are)."""
    return step.kind in (END, TIL) or (step.kind, step.action) in parent.helpful


def improving(
    ex: Expander, root: Node, clock: _Clock, bound: float, weights: tuple[float, ...]
) -> Iterator[Node]:
    """Yield goal nodes of ever shorter makespan, below `bound` (anytime weighted A*).

    A node's priority is its makespan plus a weight times the relaxed plan's duration.
    Each goal lowers the bound, which prunes every node whose partial plan is already
    as long (branch and bound), and moves to the next, smaller weight: the open list
    is reordered rather than thrown away, so no search effort is lost.
    """
    weight, later = weights[0], list(weights[1:])
    frontier: list[_Entry] = [(0.0, 0, 0, root)]
    best_span: dict[object, float] = {root.state.key(): 0.0}
    counter = 0
    while frontier:
        node = heapq.heappop(frontier)[3]
        if node.makespan >= bound - 1e-9 or best_span.get(node.state.key(), 0.0) < node.makespan:
            continue
        clock.tick()
        for state, timeline, running in ex.successors(node):
            span = timeline.makespan
            if span >= bound - 1e-9:
                continue
            key = state.key()
            known = best_span.get(key)
            if known is not None and known <= span + 1e-9:
                continue
            best_span[key] = span
            child = ex.evaluate(state, timeline, running)
            if ex.dead(child):
                continue
            if ex.reached(state):
                bound = span
                yield child
                if later:
                    weight = later.pop(0)
                    frontier = _reweigh(frontier, weight, bound)
                continue
            counter += 1
            f = span + weight * child.h_time
            heapq.heappush(frontier, (f, child.h, counter, child))


def _reweigh(frontier: list[_Entry], weight: float, bound: float) -> list[_Entry]:
    """Return the open list under a new weight, without nodes the bound prunes."""
    out = [
        (n.makespan + weight * n.h_time, h, c, n)
        for _, h, c, n in frontier
        if n.makespan < bound - 1e-9
    ]
    heapq.heapify(out)
    return out


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


def goal_agenda(ex: Expander, root: Node, clock: _Clock) -> Node | None:
    """Reach the goal facts one at a time, nearest first, by enforced hill-climbing.

    Each stage aims at the goals reached so far plus the one whose relaxed planning
    graph layer is lowest now, and continues the plan of the stage before; goals a
    stage reaches by the way count as reached. The last stage aims at the whole goal
    (with its negative and numeric parts). Each relaxed plan is then small and cheap:
    the graph stops at the stage's goals. None when a stage gets stuck (the caller
    searches for the whole goal at once instead) or the goal has fewer than two facts
    left to reach.
    """
    if (ex.task.goal & ~root.state.facts).bit_count() < 2:
        return None
    node: Node | None = root
    try:
        while node is not None and not is_goal(ex.task, node.state):
            ex.aim(agenda_stage(ex, node.state))
            start = ex.reevaluate(node)
            node = None if ex.dead(start) else enforced_hill_climbing(ex, start, clock)
        return node
    finally:
        ex.aim(None)


def agenda_stage(ex: Expander, state: State) -> int | None:
    """Return the goal agenda's next stage from `state`: the goal facts reached so far plus
    the one whose relaxed planning graph layer is lowest (ties: the lowest fact). None:
    aim at the whole goal (fewer than two goal facts left, or one is unreachable, which
    the whole goal's value then tells)."""
    goal = ex.task.goal
    remaining = goal & ~state.facts
    if remaining.bit_count() < 2:
        return None
    levels = ex.rpg.levels(state, remaining)
    if levels is None:
        return None
    nearest = min(levels, key=lambda f: (levels[f], f))
    return (goal & state.facts) | (1 << nearest)


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
PLATEAU = 1000  # expansions one climbing step of enforced hill-climbing may take
