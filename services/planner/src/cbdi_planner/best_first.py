"""Best-first searches: greedy lazy best-first search with a boosted helpful list
(complete, `search`'s fall-back), and anytime weighted A* on makespan with
branch-and-bound pruning (`improving`, shorter plans).
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Iterator

from cbdi_planner import loops
from cbdi_planner.expansion import Expander, Move, Node
from cbdi_planner.loops import Clock
from cbdi_planner.stn import END, TIL, Step

__all__ = ["best_first", "improving"]


def best_first(
    ex: Expander,
    root: Node,
    clock: Clock,
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
    ex: Expander, root: Node, clock: Clock, bound: float, weights: tuple[float, ...]
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
