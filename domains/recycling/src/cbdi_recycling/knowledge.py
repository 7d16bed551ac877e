"""The recycling robots' domain knowledge for the scheduler (`cbdi_scheduler.knowledge`).

Percepts become beliefs as `events` says (cells seen free or blocked, litter seen,
what the robot holds, which other robots it saw where: `other_in`), with obstacles and
robots out of sight remembered a while; a claim on a litter item costs the believed
path length to it (`events.Distances`, each search kept).
Exploration: the robot remembers every cell it has sensed. Once it has stood still for
`EXPLORE_AFTER` seconds with nothing in hand, and from then until it picks something up,
it believes `(explore_target CELL)`, the nearest cell it never sensed (kept until
the robot stands on it), so the recycler's `explore` rule sends an idle robot to find
litter nobody has seen yet. Waiting first keeps robots that are done for a moment (the
others finishing, a short mission) out of the others' way.
"""

from __future__ import annotations

from cbdi.beliefs import Belief, BeliefSet, fact
from cbdi.wire.world import (
    ActionOutcome,
    WorldInfo,
)
from cbdi_recycling.events import (
    Distances,
    believe_others,
    cell_name,
    exploration_target,
    map_beliefs,
    passing,
    revise_from_outcome,
    revise_from_percepts,
    seen_blocked,
    seen_others,
)
from cbdi_recycling.wire import Percepts

__all__ = ["EXPLORE_AFTER", "RecyclingKnowledge"]

EXPLORE_AFTER = 10.0  # simulated seconds standing still, hands empty, before exploring


class RecyclingKnowledge:
    """What one recycling robot's scheduler knows of its domain."""

    def __init__(self, agent: str) -> None:
        self.agent = agent
        self.distances = Distances()
        self.blocked: dict[str, float] = {}  # cell -> when last seen blocked
        self.others: dict[str, tuple[str, float]] = {}  # agent -> (cell, when) last seen
        self.sensed: set[str] = set()  # every cell sensed so far
        self.target: str | None = None  # where exploring goes next
        self.at: tuple[str, float] = ("", 0.0)  # the robot's cell, and since when
        self.exploring = False

    def map_beliefs(self, info: WorldInfo) -> list[Belief]:
        return map_beliefs(info)

    def on_percepts(self, beliefs: BeliefSet, percepts: Percepts) -> BeliefSet:
        percepts = passing(self.others, percepts)
        self.blocked = seen_blocked(self.blocked, percepts)
        revised = revise_from_percepts(beliefs, percepts, blocked=self.blocked)
        self.others = seen_others(self.others, percepts)
        revised = believe_others(revised, self.others)
        here = cell_name(percepts.position)
        self.sensed |= {cell_name(c) for c in (*percepts.free, *percepts.blocked)} | {here}
        if here != self.at[0]:
            self.at = (here, percepts.time)
        if percepts.holding:
            self.exploring = False
        elif percepts.time - self.at[1] >= EXPLORE_AFTER:
            self.exploring = True
        return self._explore(revised, here)

    def _explore(self, beliefs: BeliefSet, here: str) -> BeliefSet:
        """Believe `(explore_target CELL)`: the nearest cell never sensed when it was
        chosen, kept until the robot stands on it or sees it blocked (then the next
        nearest), or none once all were sensed. Going all the way, not just until the
        cell is seen, makes one search take the robot two cells or more instead of one."""
        if not self.exploring:
            self.target = None
        elif (
            self.target is None
            or self.target == here
            or self.target in self.blocked
            or (self.target in self.sensed and self._all_sensed(beliefs))
        ):
            bins = {f[2] for f in beliefs.facts_of("bin_pose")}
            self.target = exploration_target(
                self.distances.lengths(beliefs, here), self.sensed, bins
            )
        want = {("explore_target", self.target)} if self.target else set()
        have = set(beliefs.facts_of("explore_target"))
        if want == have:
            return beliefs
        return beliefs.removing(fact(*f) for f in have - want).adding(fact(*f) for f in want - have)

    def _all_sensed(self, beliefs: BeliefSet) -> bool:
        """Whether every cell a robot may stand on was sensed (nothing left to explore)."""
        bins = {f[2] for f in beliefs.facts_of("bin_pose")}
        cells = {n for n, t in beliefs.instances.items() if t == "cell"}
        return not cells - bins - self.sensed

    def on_outcome(self, beliefs: BeliefSet, outcome: ActionOutcome) -> BeliefSet:
        return revise_from_outcome(beliefs, outcome)

    def cost(self, beliefs: BeliefSet, agent: str, item: str) -> float:
        return self.distances(beliefs, agent, item)

    def in_hand(self, beliefs: BeliefSet, agent: str) -> set[str]:
        return {f[2] for f in beliefs.facts_of("holding") if f[1] == agent}
