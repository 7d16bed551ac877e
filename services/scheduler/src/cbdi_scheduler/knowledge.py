"""What a scheduler must know of its domain, behind one small interface.

The mind is generic: beliefs, rules, desires, intentions, claims. What only a domain
knows comes from a `DomainKnowledge` object that the domain's package provides under
the entry-point group `cbdi.knowledge`, named by the agent file's `knowledge` key:

- the beliefs the world's map gives (`map_beliefs`, the paper's `map_loaded`);
- how one epoch's percepts and an action's outcome revise the beliefs (the Events
  Monitor; it may keep memory of its own, such as obstacles seen lately);
- what a claim on a goal object costs the agent (for robots on a map: the believed path
  length to the item), so that a group shares its goals out;
- which objects the agent holds (a claim on an object in hand always wins).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol, cast

from cbdi.beliefs import Belief, BeliefSet
from cbdi.plugins import installed, load_plugin
from cbdi.wire.world import (
    ActionOutcome,
    Percept,
    WorldInfo,
)

__all__ = ["GROUP", "DomainKnowledge", "available", "load_knowledge"]

GROUP = "cbdi.knowledge"


class DomainKnowledge(Protocol):
    """One agent's knowledge of its domain (one object per agent: it may keep state)."""

    def map_beliefs(self, info: WorldInfo) -> list[Belief]:
        """The beliefs the world's map gives."""
        ...

    def on_percepts(self, beliefs: BeliefSet, percepts: Percept) -> BeliefSet:
        """`beliefs` revised with one epoch's percepts (the grid world's, or a simulator's
        generic `Sensed`)."""
        ...

    def on_outcome(self, beliefs: BeliefSet, outcome: ActionOutcome) -> BeliefSet:
        """`beliefs` revised with what an action's outcome tells and no percept shows."""
        ...

    def cost(self, beliefs: BeliefSet, agent: str, item: str) -> float:
        """What pursuing goal object `item` costs `agent` (lower wins a claim)."""
        ...

    def in_hand(self, beliefs: BeliefSet, agent: str) -> set[str]:
        """The objects `agent` holds."""
        ...


def available() -> list[str]:
    """The names of the installed domains' knowledge."""
    return installed(GROUP)


def load_knowledge(name: str, agent: str, source: str = "agent file") -> DomainKnowledge:
    """Return a new `name` knowledge for `agent`; ConfigError naming what is installed."""
    factory = load_plugin(GROUP, name, source, "knowledge", "domain knowledge")
    knowledge: DomainKnowledge = cast(Callable[[str], DomainKnowledge], factory)(agent)
    return knowledge
