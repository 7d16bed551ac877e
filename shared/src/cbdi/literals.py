"""The generic domain knowledge: percepts that are belief changes, a map that is beliefs.

A simulator hosted by the world (`cbdi.simulator`) tells its agents what they sense as
`Sensed` messages (objects seen, atoms sensed true or false, function values) and what
its map gives as `WorldInfo.instances`, `facts` and `fluents`. `LiteralKnowledge` turns
both into beliefs with no knowledge of the domain at all; an agent file names it with
`knowledge = "literals"`.

A domain that wants more (memory of what was seen, what a claim costs) subclasses it:

    class CourierKnowledge(LiteralKnowledge):
        in_hand_predicate = "carrying"      # (carrying ?robot ?parcel): claims in hand win

        def cost(self, beliefs, agent, item):
            return path_length(beliefs, agent, item)
"""

from __future__ import annotations

from cbdi.beliefs import Belief, BeliefSet, fact, fluent, instance
from cbdi.wire.world import (
    ActionOutcome,
    Percept,
    Sensed,
    WorldInfo,
)

__all__ = ["LiteralKnowledge", "map_beliefs", "revise"]


def map_beliefs(info: WorldInfo) -> list[Belief]:
    """The beliefs a simulator's map gives: its objects, atoms and function values."""
    out: list[Belief] = [instance(name, type_) for name, type_ in sorted(info.instances.items())]
    out += [fact(*atom) for atom in info.facts]
    out += [fluent(*atom, value=value) for atom, value in info.fluents]
    return out


def revise(beliefs: BeliefSet, sensed: Sensed) -> BeliefSet:
    """`beliefs` with one epoch's belief changes: objects, deletions, additions, values."""
    gone = [fact(*atom) for atom in sensed.delete if tuple(atom) in beliefs.facts]
    new = [instance(n, t) for n, t in sorted(sensed.instances.items())]
    new += [fact(*atom) for atom in sensed.add if tuple(atom) not in beliefs.facts]
    new += [
        fluent(*atom, value=value)
        for atom, value in sensed.fluents
        if beliefs.fluents.get(tuple(atom)) != value
    ]
    if not gone and not new:
        return beliefs
    return beliefs.removing(gone).adding(new)


class LiteralKnowledge:
    """One agent's knowledge of a domain whose world speaks in beliefs (`Sensed`)."""

    in_hand_predicate = ""  # `(P ?agent ?object)`: the objects an agent holds ("" none)

    def __init__(self, agent: str) -> None:
        self.agent = agent

    def map_beliefs(self, info: WorldInfo) -> list[Belief]:
        return map_beliefs(info)

    def on_percepts(self, beliefs: BeliefSet, percepts: Percept) -> BeliefSet:
        if isinstance(percepts, Sensed):
            return revise(beliefs, percepts)
        return beliefs  # the grid world's percepts: its domain's knowledge reads them

    def on_outcome(self, beliefs: BeliefSet, outcome: ActionOutcome) -> BeliefSet:
        return beliefs  # what an action did, the next percepts show

    def cost(self, beliefs: BeliefSet, agent: str, item: str) -> float:
        return 0.0  # every claim costs the same: the group's order decides

    def in_hand(self, beliefs: BeliefSet, agent: str) -> set[str]:
        if not self.in_hand_predicate:
            return set()
        return {f[2] for f in beliefs.facts_of(self.in_hand_predicate) if f[1:2] == (agent,)}
