"""searchRound (the paper's Algorithm 1): explore a bounded amount, return the best state.

The open and closed lists live in a `SearchSpace` that survives from round to round, so
no search progress is lost between rounds (Alg. 1, note after line 14). Two strategies:
`G`, enforced hill-climbing on helpful actions only (JavaFF's greedy search: fast,
incomplete), and `NG`, best-first on every successor (complete). `reroot` moves the
space's root to a state a round returned (Alg. 2 line 19): the closed list is cleared,
only open nodes whose plan starts with the new root's plan are kept, and plan sizes
count from the new root.

With `agenda`, the greedy search climbs to the goal facts one at a time, as the offline
planner's goal agenda does (`hill_climbing.goal_agenda`): it aims at the goals reached so far
plus the nearest one left (lowest relaxed-graph layer), and once a state reaches that
stage it aims at the next, climbing on from there. Each relaxed plan then stops at the
stage's goals: cheap and short-sighted in the right way on a big map with many goals.
The complete search (`NG`) always aims at the whole goal.
"""

from __future__ import annotations

import heapq
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from cbdi_planner.core import compiled
from cbdi_planner.expansion import Expander, Node
from cbdi_planner.hill_climbing import agenda_stage
from cbdi_planner.state import State, is_goal
from cbdi_planner.stn import END
from cbdi_planner.task import Task

__all__ = ["NG", "G", "Round", "RoundBound", "SearchSpace"]

G, NG = "G", "NG"


@dataclass(frozen=True, slots=True)
class RoundBound:
    """When a round stops: seconds (INTERVAL), node expansions, and actions in the best
    state's plan counted from the root (PLAN_SIZE_LIMIT). None: no bound of that kind.

    Expansions make rounds deterministic (tests and experiments); seconds are what a
    running agent uses.
    """

    seconds: float | None = None
    expansions: int | None = None
    plan_size: int | None = None


@dataclass(frozen=True, slots=True)
class Round:
    """What one round found: `kind` is `goal` (Alg. 1 line 8), `best` (lines 9-11: the
    most promising state, possibly the root itself) or `exhausted` (line 16: the open list
    ran empty). `node` is the goal or best node; `expanded` counts this round only.
    """

    kind: str
    node: Node | None
    expanded: int
    seconds: float
    best_h: int


def plan_size(node: Node, root_steps: int) -> int:
    """Return the number of actions started in `node`'s plan after the root."""
    return sum(1 for s in node.timeline.steps[root_steps:] if s.kind != END)


class SearchSpace:
    """The open and closed lists of one continual search, rooted at `root`.

    In `G` the open list is the breadth-first queue of enforced hill-climbing (JavaFF's
    greedy search, which CJFF runs first): successors by helpful actions only, and the
    first one strictly better than the climber (`current`) becomes the climber and
    empties the queue. In `NG` it is a best-first priority queue on h (ties: shorter
    plans) over every successor, which is complete.
    """

    def __init__(
        self,
        task: Task,
        state: State,
        *,
        mode: str = G,
        epsilon: float = 0.001,
        now: Callable[[], float] = time.monotonic,
        agenda: bool = False,
    ) -> None:
        if mode not in (G, NG):
            raise ValueError(f"unknown search mode {mode!r} (G or NG)")
        self.task, self.mode, self.now = task, mode, now
        self.agenda = agenda
        self.expander = Expander(task, epsilon)
        if state.open:
            raise ValueError("a search root cannot have running actions")
        self._aim_at(state)
        self.root = self.expander.root(state)
        self.root_steps = 0  # timeline steps before the root (the prefix cut off)
        self.open: list[tuple[int, int, int, Node]] = []  # NG
        self.queue: deque[Node] = deque()  # G
        self.current = self.root  # G: the hill-climber's node
        self.closed: set[object] = set()
        self.counter = 0
        self.expanded = 0
        self.best = self.root  # the round's best state so far
        self._push(self.root)
        # The compiled core's lists (`cbdi_planner_core.Rounds`), when it runs: a round
        # is then one call, and the lists above stay empty.
        self._native: Any = None
        module = compiled()
        if self.expander.native is not None and module is not None:
            self._native = module.Rounds(self.expander.native, self.root.handle, mode, agenda)

    def _push(self, node: Node) -> None:
        if self.mode == G:
            self.queue.append(node)
            return
        self.counter += 1
        heapq.heappush(self.open, (node.h, len(node.timeline.steps), self.counter, node))

    def _pop(self) -> Node:
        return self.queue.popleft() if self.mode == G else heapq.heappop(self.open)[3]

    def _unpop(self, node: Node) -> None:
        if self.mode == G:
            self.queue.appendleft(node)
        else:
            self._push(node)

    def _has_open(self) -> bool:
        return bool(self.queue) if self.mode == G else bool(self.open)

    def _clear_open(self) -> None:
        self.open, self.queue = [], deque()

    def search_round(self, bound: RoundBound) -> Round:
        """Run Algorithm 1 from the root until the goal, a bound, or an empty open list."""
        if self._native is not None:
            return self._native_round(bound)
        started, expanded = self.now(), 0
        self.best = self.root  # line 1
        if self.expander.dead(self.root):
            self._clear_open()
        while self._has_open():  # line 4
            node = self._pop()  # line 5
            key = node.state.key()
            if key in self.closed:
                continue
            self.closed.add(key)
            self._consider(node)  # lines 6-7
            if is_goal(self.task, node.state):  # line 8
                return self._done("goal", node, expanded, started)
            if self.expander.subgoal is not None and self.expander.reached(node.state):
                node = self._next_stage(node)
            if self._bound_hit(bound, self.best, expanded, started):  # lines 9-11
                # `node` is not expanded yet: it stays open for the next round.
                self.closed.discard(key)
                self._unpop(node)
                return self._done("best", self.best, expanded, started)
            expanded += 1
            self._expand(node)  # lines 12-14
        if self.best is not self.root:
            return self._done("best", self.best, expanded, started)
        return self._done("exhausted", None, expanded, started)  # line 16

    def _native_round(self, bound: RoundBound) -> Round:
        """`search_round` by the compiled core, in one call."""
        started = self.now()
        timed = self.now if bound.seconds is not None else None
        try:
            kind, handle, is_root, expanded, best_h = self._native.search_round(
                bound.seconds, bound.expansions, bound.plan_size, timed, started
            )
        finally:
            self.expander.sync()
            self._sync_aim()
        node = None
        if handle is not None:
            node = self.root if is_root else self.expander.node_of(handle)
        self.expanded += expanded
        return Round(kind, node, expanded, self.now() - started, best_h)

    def _sync_aim(self) -> None:
        """Let the expander aim where the compiled core's rounds aim."""
        stage = self.expander.native.subgoal
        aim = None if stage is None else sum(1 << f for f in stage)
        if aim != self.expander.subgoal:
            self.expander.aim(aim)

    def _aim_at(self, state: State) -> None:
        """Aim the heuristic at the agenda's next stage from `state` (greedy mode with an
        agenda), else at the whole goal."""
        greedy = self.agenda and self.mode == G
        self.expander.aim(agenda_stage(self.expander, state) if greedy else None)

    def _next_stage(self, node: Node) -> Node:
        """`node` reached the agenda's stage: aim at the next and climb on from `node`,
        evaluated again (a value under one aim says nothing under another)."""
        self._aim_at(node.state)
        node = self.expander.evaluate(node.state, node.timeline, node.running)
        self.current, self.best = node, node
        self.queue = deque()
        self.closed = {node.state.key()}
        return node

    def _consider(self, node: Node) -> None:
        """Lines 6-7: the best state has the lowest h and no running action. Successors
        count as soon as they are evaluated, so a round cut short by its interval still
        hands out what its last expansion found."""
        if not node.running and node.h < self.best.h:
            self.best = node

    def _bound_hit(self, bound: RoundBound, best: Node, expanded: int, started: float) -> bool:
        if bound.seconds is not None and self.now() - started >= bound.seconds:
            return True  # line 9: INTERVAL
        if bound.expansions is not None and expanded >= bound.expansions:
            return True
        limit = bound.plan_size  # lines 10-11: PLAN_SIZE_LIMIT
        return limit is not None and plan_size(best, self.root_steps) >= limit

    def _expand(self, node: Node) -> None:
        """searchCoreLogic: G keeps helpful successors only, NG every successor."""
        greedy = self.mode == G
        for state, timeline, running in self.expander.successors(node, greedy):
            if state.key() in self.closed:  # needToVisit
                continue
            child = self.expander.evaluate(state, timeline, running)
            if self.expander.dead(child):
                continue
            self._consider(child)
            if greedy and child.h < self.current.h:
                # Enforced hill-climbing: climb to the better node, forget the plateau.
                self.current = child
                self.queue.clear()
                self.queue.append(child)
                break
            self._push(child)
        self.expanded += 1

    def _done(self, kind: str, node: Node | None, expanded: int, started: float) -> Round:
        best_h = node.h if node is not None else self.root.h
        return Round(kind, node, expanded, self.now() - started, best_h)

    def reroot(self, node: Node) -> None:
        """Alg. 2 line 19: root the search at `node` (a state with no running action)."""
        if node.running:
            raise ValueError("cannot re-root on a state with running actions")
        if self._native is not None:
            self._native.reroot(node.handle)
            self.root, self.root_steps = node, len(node.timeline.steps)
            return
        prefix = node.timeline.steps

        def extends(n: Node) -> bool:
            steps = n.timeline.steps
            return len(steps) > len(prefix) and all(
                a is b for a, b in zip(steps, prefix, strict=False)
            )

        self.open = [entry for entry in self.open if extends(entry[3])]
        heapq.heapify(self.open)
        self.queue = deque(n for n in self.queue if extends(n))
        if not extends(self.current):
            self.current, self.queue = node, deque()
        self.closed = set()
        self.root, self.root_steps = node, len(prefix)
        self._push(node)

    def restart(self, mode: str, root: Node) -> None:
        """Search again in `mode` from `root` (a node of this space) with empty lists."""
        self.mode = mode
        if self._native is not None:
            root = self.expander.node_of(self._native.restart(mode, root.handle))
            self._sync_aim()
            self.root, self.current = root, root
            self.root_steps = len(root.timeline.steps)
            return
        self._aim_at(root.state)
        root = self.expander.evaluate(root.state, root.timeline, root.running)
        self.root, self.current = root, root
        self.root_steps = len(root.timeline.steps)
        self._clear_open()
        self.closed = set()
        self._push(root)

    def new_steps(self, node: Node) -> range:
        """Return the indexes of `node`'s timeline steps after the root (its new plan)."""
        return range(self.root_steps, len(node.timeline.steps))
