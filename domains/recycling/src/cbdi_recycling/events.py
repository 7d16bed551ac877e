"""The recycling Events Monitor: turn the world's percepts into belief revisions.

Within the sensed square the percepts are the truth: `free` cells are believed free and
every other cell of the square not free; litter seen is believed where it is seen, and a
believed item no longer seen in the square is forgotten there. Outside the square the
agent assumes free space: people and robots move, so an obstacle once seen is forgotten
`OBSTACLE_MEMORY` seconds after it was last seen (a cell believed blocked for good would
wall the robot in; one forgotten the moment it is out of sight makes a robot turn back
and forth between a short way it cannot see is blocked and a detour), and only bins
block for good. Another robot seen moving on (`passing`) blocks nothing: the plan
forecast past it would be repaired for nothing. The agent's own cell, what it holds and
its load (`loaded_amount`) come with every percept.
"""

from __future__ import annotations

from collections.abc import Collection

import msgspec

from cbdi.beliefs import Belief, BeliefSet, fact, fluent, instance
from cbdi.wire.world import (
    ActionOutcome,
    Cell,
    WorldInfo,
)
from cbdi_recycling.wire import Percepts, grid_map

__all__ = [
    "OBSTACLE_MEMORY",
    "PASSING",
    "UNKNOWN_DISTANCE",
    "Distances",
    "believe_others",
    "cell_name",
    "distance",
    "exploration_target",
    "map_beliefs",
    "passing",
    "revise_from_outcome",
    "revise_from_percepts",
    "seen_blocked",
    "seen_others",
]


def cell_name(cell: Cell) -> str:
    """Return the PDDL object of a cell (`c_X_Y`, as in the paper's problems)."""
    return f"c_{cell[0]}_{cell[1]}"


def _stale(atom: tuple[str, ...], square: set[str], me: str) -> bool:
    """Return whether this epoch's percepts replace what `atom` said."""
    name, args = atom[0], atom[1:]
    if name == "free":
        return args[0] in square
    if name == "litter_pose":
        return args[1] in square
    return name in ("in", "holding") and args[0] == me


OBSTACLE_MEMORY = 8.0  # simulated seconds an obstacle out of sight is still believed


def seen_blocked(
    memory: dict[str, float], p: Percepts, keep: float = OBSTACLE_MEMORY
) -> dict[str, float]:
    """Return when each cell was last seen blocked, with this epoch's percepts, leaving
    out cells seen free now and those not seen blocked for `keep` seconds."""
    out = {c: t for c, t in memory.items() if p.time - t < keep}
    for c in p.free:
        out.pop(cell_name(c), None)
    out.pop(cell_name(p.position), None)
    for c in p.blocked:
        out[cell_name(c)] = p.time
    return out


def revise_from_percepts(
    beliefs: BeliefSet,
    p: Percepts,
    litter_type: str = "plastic",
    blocked: Collection[str] = (),
) -> BeliefSet:
    """Return `beliefs` revised with one epoch's percepts of agent `p.agent`; cells in
    `blocked` (seen blocked lately, `seen_blocked`) stay not free out of sight."""
    square = {cell_name(c) for c in (*p.free, *p.blocked, p.position)}
    me = p.agent
    stale = [
        fact(*atom)
        for name in ("free", "litter_pose", "in", "holding")  # what `_stale` may replace
        for atom in beliefs.facts_of(name)
        if _stale(atom, square, me)
    ]
    fresh = [fact("free", cell_name(c)) for c in p.free]
    bins = {f[2] for f in beliefs.facts_of("bin_pose")}
    unseen = {n for n, t in beliefs.instances.items() if t == "cell"} - square - bins
    unseen -= set(blocked)
    fresh += [fact("free", c) for c in sorted(unseen) if ("free", c) not in beliefs.facts]
    fresh.append(fact("in", me, cell_name(p.position)))
    for item in p.items:
        fresh += [
            instance(item.name, litter_type),
            fact("litter_pose", item.name, cell_name(item.cell)),
        ]
    for held in p.holding:
        fresh += [instance(held, litter_type), fact("holding", me, held)]
    fresh.append(fluent("loaded_amount", me, value=float(len(p.holding))))
    return beliefs.removing(stale).adding(fresh)


def seen_others(
    memory: dict[str, tuple[str, float]], p: Percepts, keep: float = OBSTACLE_MEMORY
) -> dict[str, tuple[str, float]]:
    """Return where and when each other agent was last seen, with this epoch's percepts,
    leaving out those not seen for `keep` seconds: a robot that made way one cell back
    is out of a depth-1 sight at once, and one forgotten then walked back into the way."""
    out = {a: (c, t) for a, (c, t) in memory.items() if p.time - t < keep}
    for o in p.others:
        out[o.name] = (cell_name(o.cell), p.time)
    return out


PASSING = 1.5  # simulated seconds: a robot seen elsewhere this lately is on its way


def passing(memory: dict[str, tuple[str, float]], p: Percepts, keep: float = PASSING) -> Percepts:
    """Return `p` with the cells of robots passing by sensed free: another robot seen in
    another cell at its last sighting (`seen_others`, at most `keep` seconds ago) whose
    next cell on the same heading is not this robot's is moving on (ahead, away or
    across), so the cell it stands on is no obstacle to forecast a plan on. A robot
    standing still, seen for the first time, or heading into this robot's cell still
    blocks its cell.
    """
    here = tuple(p.position)
    gone = set()
    for o in p.others:
        last = memory.get(o.name)
        if last is None or last[0] == cell_name(o.cell) or p.time - last[1] > keep:
            continue
        before = _cell_of(last[0])
        ahead = (2 * o.cell[0] - before[0], 2 * o.cell[1] - before[1])
        if ahead != here:
            gone.add(tuple(o.cell))
    if not gone:
        return p
    blocked = [c for c in p.blocked if tuple(c) not in gone]
    free = [*p.free, *(c for c in p.blocked if tuple(c) in gone)]
    return msgspec.structs.replace(p, blocked=blocked, free=free)


def _cell_of(name: str) -> tuple[int, int]:
    """The cell a `c_X_Y` object names (`cell_name`'s inverse)."""
    _, x, y = name.split("_")
    return int(x), int(y)


def believe_others(beliefs: BeliefSet, others: dict[str, tuple[str, float]]) -> BeliefSet:
    """Return `beliefs` with `(other_in AGENT CELL)` for each agent seen lately (where it
    was last seen, `seen_others`) and for no other: which robot may stand in the way, so
    that a robot held up by another can ask it to make way (the recycler's `ask_way`)."""
    have = set(beliefs.facts_of("other_in"))
    want = {("other_in", a, c) for a, (c, _) in others.items()}
    if have == want:
        return beliefs
    return beliefs.removing(fact(*f) for f in have - want).adding(
        fact(*f) for f in sorted(want - have)
    )


def revise_from_outcome(beliefs: BeliefSet, outcome: ActionOutcome) -> BeliefSet:
    """Return `beliefs` revised with an action's outcome: what no percept shows.

    A recycled item is in a bin, out of sight: only the outcome tells.
    """
    if outcome.status == "succeeded" and outcome.action == "recycle" and outcome.item:
        return beliefs.adding([fact("recycled", outcome.item)])
    return beliefs


def map_beliefs(
    info: WorldInfo, bin_type: str = "bin", litter_type: str = "plastic"
) -> list[Belief]:
    """Return what an agent believes once it loaded the map (the paper's `map_loaded`).

    Every cell that is not a wall is a `cell`, with `near` facts between 4-adjacent ones;
    bins are placed; every cell that holds neither wall nor bin is believed free until
    sensing says otherwise (people and robots are seen, not known in advance). Litter the
    world marks as known at the start is believed where it lies.
    """
    grid = grid_map(info)
    walls: set[Cell] = {(w[0], w[1]) for w in grid.walls}
    bins: dict[Cell, str] = {(b.cell[0], b.cell[1]): b.name for b in grid.bins}
    cells = [(x, y) for y in range(grid.height) for x in range(grid.width) if (x, y) not in walls]
    out: list[Belief] = [fact("map_loaded")]
    for c in cells:
        out.append(instance(cell_name(c), "cell"))
        if c not in bins:
            out.append(fact("free", cell_name(c)))
        for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            n = (c[0] + dx, c[1] + dy)
            if n in walls or not (0 <= n[0] < grid.width and 0 <= n[1] < grid.height):
                continue
            out.append(fact("near", cell_name(c), cell_name(n)))
    for cell, name in bins.items():
        out += [instance(name, bin_type), fact("bin_pose", name, cell_name(cell))]
    for item in info.known_items:  # the paper's known litter, given at the start
        out += [
            instance(item.name, litter_type),
            fact("litter_pose", item.name, cell_name((item.cell[0], item.cell[1]))),
        ]
    return out


UNKNOWN_DISTANCE = 1e9  # finite: it travels in JSON exports too


class Distances:
    """Path lengths over the believed `near` graph, searched once per source cell.

    The `near` facts come from the map and do not change during a run: the graph is
    built once, and each breadth-first search from a cell is kept (up to `keep` cells),
    so a claim costs a dictionary lookup. If the `near` facts do change, the graph and
    the searches are rebuilt.
    """

    def __init__(self, keep: int = 64) -> None:
        self.keep = keep
        self._near_count = -1
        self._graph: dict[str, list[str]] = {}
        self._from: dict[str, dict[str, int]] = {}
        self._facts: frozenset[tuple[str, ...]] | None = None
        self._at: dict[str, str] = {}  # agent or item -> its believed cell

    def _refresh(self, beliefs: BeliefSet) -> None:
        if beliefs.facts is self._facts:
            return
        self._facts = beliefs.facts
        near, self._at = [], {}
        for f in beliefs.facts:
            if f[0] == "near":
                near.append(f)
            elif f[0] in ("in", "litter_pose") and len(f) == 3:
                self._at[f[1]] = f[2]
        if len(near) == self._near_count:
            return
        graph: dict[str, list[str]] = {}
        for f in sorted(near):
            graph.setdefault(f[1], []).append(f[2])
        self._graph, self._from, self._near_count = graph, {}, len(near)

    def lengths(self, beliefs: BeliefSet, here: str) -> dict[str, int]:
        """Return the path length from `here` to every cell it reaches."""
        self._refresh(beliefs)
        known = self._from.get(here)
        if known is not None:
            return known
        lengths = {here: 0}
        frontier = [here]
        while frontier:
            nxt = []
            for c in frontier:
                for n in self._graph.get(c, ()):
                    if n not in lengths:
                        lengths[n] = lengths[c] + 1
                        nxt.append(n)
            frontier = nxt
        if len(self._from) >= self.keep:
            self._from.pop(next(iter(self._from)))
        self._from[here] = lengths
        return lengths

    def __call__(self, beliefs: BeliefSet, agent: str, item: str) -> float:
        """Return the believed path length (over `near`) from `agent` to litter `item`:
        0 if it holds it, UNKNOWN_DISTANCE if either place or a path is unknown."""
        if ("holding", agent, item) in beliefs.facts:
            return 0.0
        self._refresh(beliefs)
        here, there = self._at.get(agent), self._at.get(item)
        if here is None or there is None:
            return UNKNOWN_DISTANCE
        steps = self.lengths(beliefs, here).get(there)
        return UNKNOWN_DISTANCE if steps is None else float(steps)


def distance(beliefs: BeliefSet, agent: str, item: str) -> float:
    """Return the believed path length from `agent` to litter `item` (one search)."""
    return Distances(keep=1)(beliefs, agent, item)


def exploration_target(
    lengths: dict[str, int], sensed: Collection[str], bins: Collection[str]
) -> str | None:
    """Return the nearest cell (path length, then name) never sensed that a robot can
    stand on, from the path `lengths` of its cell; None when it has sensed them all."""
    best: tuple[int, str] | None = None
    for cell, steps in lengths.items():
        if cell in sensed or cell in bins:
            continue
        if best is None or (steps, cell) < best:
            best = (steps, cell)
    return None if best is None else best[1]
