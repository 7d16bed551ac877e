"""A scripted agent's mind: beliefs from percepts and a greedy recycling policy.

Not a BDI agent (that is the scheduler/planner/executor trio): a stand-in that drives a
robot through the world over the real bus, for the demo and end-to-end tests. It either
follows a fixed script of steps, or greedily fetches the nearest known litter (up to its
capacity), carries it next to a bin, recycles it, and explores cells it has never sensed.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass, field

from cbdi.wire.world import (
    Cell,
)
from cbdi_recycling.wire import Percepts

__all__ = ["Beliefs", "Step", "greedy_step", "next_hop", "parse_script"]

_DIRS = ((1, 0), (-1, 0), (0, 1), (0, -1))


@dataclass(frozen=True)
class Step:
    """One action to request: `move` (with target), `pickup` or `recycle` (item optional)."""

    action: str
    target: Cell | None = None
    item: str | None = None


@dataclass
class Beliefs:
    """What the scripted agent believes about the world (static map + what it sensed)."""

    width: int
    height: int
    walls: frozenset[Cell]
    bins: frozenset[Cell]
    capacity: int = 3
    position: Cell | None = None
    holding: tuple[str, ...] = ()
    litter: dict[str, Cell] = field(default_factory=dict)
    blocked: set[Cell] = field(default_factory=set)
    sensed: set[Cell] = field(default_factory=set)

    def revise(self, p: Percepts) -> None:
        """Revise beliefs with this epoch's percepts (the square around the agent)."""
        self.position = p.position
        self.holding = tuple(p.holding)
        square = {*p.free, *p.blocked, p.position}
        self.sensed |= square
        seen = {item.name: item.cell for item in p.items}
        for name, cell in list(self.litter.items()):
            if cell in square and name not in seen:
                del self.litter[name]
        self.litter.update(seen)
        self.blocked = set(p.blocked) - self.walls - self.bins

    def passable(self, cell: Cell) -> bool:
        x, y = cell
        return (
            0 <= x < self.width
            and 0 <= y < self.height
            and cell not in self.walls
            and cell not in self.bins
            and cell not in self.blocked
        )

    def next_to_bin(self, cell: Cell) -> bool:
        return any((cell[0] + dx, cell[1] + dy) in self.bins for dx, dy in _DIRS)


def next_hop(b: Beliefs, goals: Iterable[Cell]) -> Cell | None:
    """Return the first cell of a shortest path to any goal (BFS), or None if none is reachable."""
    start = b.position
    targets = set(goals)
    if start is None or not targets or start in targets:
        return None
    parent: dict[Cell, Cell] = {start: start}
    frontier = deque([start])
    while frontier:
        cell = frontier.popleft()
        for dx, dy in _DIRS:
            nxt = (cell[0] + dx, cell[1] + dy)
            if nxt in parent or not b.passable(nxt):
                continue
            parent[nxt] = cell
            if nxt in targets:
                while parent[nxt] != start:
                    nxt = parent[nxt]
                return nxt
            frontier.append(nxt)
    return None


def greedy_step(b: Beliefs) -> Step | None:
    """Choose the next step: pick up here, recycle here, or move toward litter/bin/unknown."""
    if b.position is None:
        return None
    here = [n for n, c in sorted(b.litter.items()) if c == b.position]
    if here and len(b.holding) < b.capacity:
        return Step("pickup", item=here[0])
    if b.holding and b.next_to_bin(b.position) and (len(b.holding) >= b.capacity or not b.litter):
        return Step("recycle", item=b.holding[0])
    if b.litter and len(b.holding) < b.capacity:
        hop = next_hop(b, b.litter.values())
        if hop is not None:
            return Step("move", target=hop)
    if b.holding:
        if b.next_to_bin(b.position):
            return Step("recycle", item=b.holding[0])
        hop = next_hop(b, _bin_sides(b))
        return Step("move", target=hop) if hop else None
    unknown = [
        (x, y)
        for x in range(b.width)
        for y in range(b.height)
        if (x, y) not in b.sensed
        and (x, y) not in b.walls
        and (x, y) not in b.bins
        and (x, y) != b.position
    ]
    hop = next_hop(b, unknown)
    return Step("move", target=hop) if hop else None


def _bin_sides(b: Beliefs) -> list[Cell]:
    return [(x + dx, y + dy) for x, y in b.bins for dx, dy in _DIRS]


def parse_script(text: str) -> list[Step]:
    """Parse `move:1,0 move:2,0 pickup recycle` (separated by spaces or `;`) into steps."""
    steps: list[Step] = []
    for token in text.replace(";", " ").split():
        name, _, arg = token.partition(":")
        if name == "move":
            try:
                x, y = (int(v) for v in arg.split(","))
            except ValueError:
                raise ValueError(f"script step {token!r}: expected move:X,Y") from None
            steps.append(Step("move", target=(x, y)))
        elif name in ("pickup", "recycle"):
            steps.append(Step(name, item=arg or None))
        else:
            raise ValueError(f"script step {token!r}: expected move:X,Y, pickup or recycle")
    return steps
