"""A lower bound on a recycling fleet's mission time, from the map alone.

No schedule of N robots can recycle every item sooner than either term below; the bound
is the larger. Distances are shortest paths on the grid (4-neighbours; walls and bin
cells are never entered), in moves of `move` seconds; people, sensing and the other
robots are ignored (they only make the real runs longer), and litter to be discovered
counts as known (a clairvoyant fleet).

- **Longest job** (`trip`): an item needs some robot to come to its cell, pick it up,
  and carry it to a cell next to a bin and recycle it:
  `max over items of [min over the N starts of d(start, item)] + pickup
  + d(item, bin side) + recycle`.
- **Work shared** (`work`): every item's pickup and recycle, the way to its cell, and
  the ways to the bins: a robot arrives at an item's cell from its start, another item's
  cell or a bin side (where it recycled), so at least the least of those distances
  `a(item)`; and it carries at most `capacity` items, so its recycles come in at least
  `ceil(items / capacity)` runs, each reached from the cell of a distinct item picked up
  last, at least that item's distance to a bin side (the smallest such distances, one per
  run). These stretches end at distinct events (a pickup, a run's first recycle), so
  they are disjoint parts of the robots' time, and the total divided by N bounds the
  mission: `(sum of a(item) + sum of the runs' ways) * move / N + items * (pickup +
  recycle) / N`.
"""

from __future__ import annotations

import math
import tomllib
from collections import deque
from dataclasses import dataclass
from pathlib import Path

from cbdi_recycling.maps import WorldMap, load_map

__all__ = ["Bound", "fleet_bound", "scenario_map"]

Cell = tuple[int, int]


@dataclass(frozen=True)
class Bound:
    """The bound (simulated seconds) and its two terms."""

    trip: float
    work: float

    @property
    def value(self) -> float:
        return max(self.trip, self.work)

    @property
    def term(self) -> str:
        """Which term decides: `trip` or `work`."""
        return "trip" if self.trip >= self.work else "work"


def scenario_map(scenario: Path) -> WorldMap:
    """Load the map a recycling scenario file names (relative to the file)."""
    with scenario.open("rb") as handle:
        data = tomllib.load(handle)
    return load_map(scenario.parent / data["map"])


def _distances(m: WorldMap, sources: list[Cell]) -> dict[Cell, int]:
    """Moves from the nearest of `sources` to every reachable cell (breadth-first)."""
    blocked = set(m.walls) | set(m.bins.values())
    out = {s: 0 for s in sources}
    queue = deque(sources)
    while queue:
        x, y = queue.popleft()
        for nxt in ((x + 1, y), (x - 1, y), (x, y + 1), (x, y - 1)):
            if nxt in out or nxt in blocked or not m.inside(nxt):
                continue
            out[nxt] = out[(x, y)] + 1
            queue.append(nxt)
    return out


def fleet_bound(m: WorldMap, robots: int) -> Bound:
    """The lower bound of the module for `robots` robots on the map's first start cells."""
    if not 1 <= robots <= len(m.agent_starts):
        raise ValueError(f"{robots} robots: the map has {len(m.agent_starts)} start cells")
    move, pickup, recycle = (m.durations[k] for k in ("move", "pickup", "recycle"))
    starts = list(m.agent_starts[:robots])
    blocked = set(m.walls) | set(m.bins.values())
    sides = sorted(
        {
            (x + dx, y + dy)
            for x, y in m.bins.values()
            for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1))
            if (x + dx, y + dy) not in blocked and m.inside((x + dx, y + dy))
        }
    )
    items = [cell for cell, _ in m.litter.values()]
    from_start = _distances(m, starts)
    to_bin = _distances(m, sides)
    unreachable = [c for c in items if c not in from_start or c not in to_bin]
    if unreachable:
        raise ValueError(f"litter at {unreachable} cannot be reached or brought to a bin")
    trip = max(
        (from_start[c] * move + pickup + to_bin[c] * move + recycle for c in items), default=0.0
    )
    moves = 0
    for i, cell in enumerate(items):
        others = [c for j, c in enumerate(items) if j != i]
        near = _distances(m, [cell])
        moves += min([from_start[cell], to_bin[cell], *(near[c] for c in others if c in near)])
    runs = math.ceil(len(items) / max(m.capacity, 1))
    moves += sum(sorted(to_bin[c] for c in items)[:runs])
    work = moves * move + len(items) * (pickup + recycle)
    return Bound(trip=trip, work=work / robots)
