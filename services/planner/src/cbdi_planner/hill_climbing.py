"""Enforced hill-climbing (FF's), and the goal agenda that climbs to one goal fact at a
time, nearest first: the fast, incomplete searches `search` tries first.
"""

from __future__ import annotations

from collections import deque

from cbdi_planner import loops
from cbdi_planner.expansion import Expander, Node
from cbdi_planner.loops import Clock
from cbdi_planner.state import State, is_goal

__all__ = ["PLATEAU", "agenda_stage", "enforced_hill_climbing", "goal_agenda"]

PLATEAU = 1000  # expansions one climbing step of enforced hill-climbing may take


def enforced_hill_climbing(ex: Expander, root: Node, clock: Clock) -> Node | None:
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


def _climb(ex: Expander, current: Node, clock: Clock, helpful_only: bool) -> Node | None:
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


def goal_agenda(ex: Expander, root: Node, clock: Clock) -> Node | None:
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
