"""The courier robots' knowledge for the scheduler: the generic literal knowledge
(`cbdi.literals`), with what a claim costs and what a robot holds.

A claim on a parcel costs the believed number of drives to it (breadth-first over the
`link` facts, through cells believed clear); a parcel in hand costs nothing. A cell seen
taken (a robot, the cart) and then out of sight for `FORGET_AFTER` seconds is believed
clear again: what moves has moved on, and a robot that remembered every obstacle it
ever saw would wall itself in.
"""

from __future__ import annotations

from collections import deque

from cbdi.beliefs import BeliefSet, fact
from cbdi.literals import LiteralKnowledge
from cbdi.wire.world import (
    Percept,
    Sensed,
)

__all__ = ["FORGET_AFTER", "CourierKnowledge", "drives"]

_FAR = 1e6
FORGET_AFTER = 6.0  # simulated seconds out of sight before a taken cell is believed clear


def drives(beliefs: BeliefSet, start: str, goal: str) -> float:
    """The fewest drives from cell `start` to cell `goal` over believed passable cells."""
    if start == goal:
        return 0.0
    links: dict[str, list[str]] = {}
    for _, a, b in beliefs.facts_of("link"):
        links.setdefault(a, []).append(b)
    seen, queue = {start}, deque([(start, 0)])
    while queue:
        cell, n = queue.popleft()
        for nxt in links.get(cell, ()):
            if nxt == goal:
                return float(n + 1)
            if nxt in seen or ("clear", nxt) not in beliefs.facts:
                continue
            seen.add(nxt)
            queue.append((nxt, n + 1))
    return _FAR


class CourierKnowledge(LiteralKnowledge):
    """What one courier robot's scheduler knows of its domain."""

    in_hand_predicate = "carrying"

    def __init__(self, agent: str) -> None:
        super().__init__(agent)
        self.taken: dict[str, float] = {}  # cell -> when last seen taken

    def on_percepts(self, beliefs: BeliefSet, percepts: Percept) -> BeliefSet:
        revised = super().on_percepts(beliefs, percepts)
        if not isinstance(percepts, Sensed):
            return revised
        now = percepts.time
        seen = {a[1] for a in (*percepts.add, *percepts.delete) if a[0] == "clear" and len(a) == 2}
        for atom in percepts.delete:
            if atom[0] == "clear" and len(atom) == 2:
                self.taken[atom[1]] = now
        for cell in seen - {a[1] for a in percepts.delete if a[0] == "clear"}:
            self.taken.pop(cell, None)
        stale = sorted(
            c for c, t in self.taken.items() if c not in seen and now - t >= FORGET_AFTER
        )
        for cell in stale:
            del self.taken[cell]
        if not stale:
            return revised
        return revised.adding(fact("clear", c) for c in stale)

    def cost(self, beliefs: BeliefSet, agent: str, item: str) -> float:
        if ("carrying", agent, item) in beliefs.facts:
            return 0.0
        here = next((f[2] for f in beliefs.facts_of("at") if f[1] == agent), None)
        there = next((f[2] for f in beliefs.facts_of("parcel_at") if f[1] == item), None)
        if here is None or there is None:
            return _FAR
        return drives(beliefs, here, there)
