"""The recycling robots' domain knowledge for the scheduler (`cbdi_scheduler.knowledge`).

Percepts become beliefs as `events` says (cells seen free or blocked, litter seen,
what the robot holds), with obstacles out of sight remembered a while; a claim on a
litter item costs the believed path length to it (`events.Distances`, each search kept).
"""

from __future__ import annotations

from cbdi.beliefs import Belief, BeliefSet
from cbdi.wire.world import ActionOutcome, Percepts, WorldInfo
from cbdi_recycling.events import (
    Distances,
    map_beliefs,
    revise_from_outcome,
    revise_from_percepts,
    seen_blocked,
)

__all__ = ["RecyclingKnowledge"]


class RecyclingKnowledge:
    """What one recycling robot's scheduler knows of its domain."""

    def __init__(self, agent: str) -> None:
        self.agent = agent
        self.distances = Distances()
        self.blocked: dict[str, float] = {}  # cell -> when last seen blocked

    def map_beliefs(self, info: WorldInfo) -> list[Belief]:
        return map_beliefs(info)

    def on_percepts(self, beliefs: BeliefSet, percepts: Percepts) -> BeliefSet:
        self.blocked = seen_blocked(self.blocked, percepts)
        return revise_from_percepts(beliefs, percepts, blocked=self.blocked)

    def on_outcome(self, beliefs: BeliefSet, outcome: ActionOutcome) -> BeliefSet:
        return revise_from_outcome(beliefs, outcome)

    def cost(self, beliefs: BeliefSet, agent: str, item: str) -> float:
        return self.distances(beliefs, agent, item)

    def holding(self, beliefs: BeliefSet, agent: str) -> set[str]:
        return {f[2] for f in beliefs.facts_of("holding") if f[1] == agent}
