"""Claims: how agents of one group avoid pursuing the same goal object (pure logic).

An agent file lists claimable goal predicates (`[scheduler] claim = ["recycled"]`). When
a desire's goal holds an atom of one (`(recycled pla61)`), the agent claims its first
argument (the item) in its group: it tells every agent of the group, who tell it of
theirs. The owner of an item is the agent with the earliest claim (epoch, then name, so
every agent decides alike without a further round of messages); an agent strips the
atoms of items others own from its desires, and drops a desire left with no goal. A
claim is released when the agent gives the atom up (its desire dropped), so another
agent may take the item.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

from cbdi.wire.agent import Claim

__all__ = ["Claims"]


@dataclass
class Claims:
    """This agent's view of the claims in its group."""

    agent: str
    group: str
    predicates: frozenset[str]
    held: dict[str, dict[str, int]] = field(default_factory=dict)  # item -> agent -> epoch

    def claimable(self, atom: tuple[str, ...]) -> str | None:
        """Return the item `atom` claims, or None if its predicate is not claimable."""
        if atom[0] in self.predicates and len(atom) > 1:
            return atom[1]
        return None

    def claim(self, atoms: Iterable[tuple[str, ...]], epoch: int) -> list[Claim]:
        """Claim the items of `atoms` not claimed by this agent yet; return the messages."""
        out = []
        for atom in atoms:
            item = self.claimable(atom)
            if item is None or self.agent in self.held.get(item, {}):
                continue
            self.held.setdefault(item, {})[self.agent] = epoch
            out.append(Claim(agent=self.agent, group=self.group, item=item, epoch=epoch))
        return out

    def release(self, atoms: Iterable[tuple[str, ...]]) -> list[Claim]:
        """Give up this agent's claims on the items of `atoms`; return the messages."""
        out = []
        for atom in atoms:
            item = self.claimable(atom)
            if item is None or self.held.get(item, {}).pop(self.agent, None) is None:
                continue
            out.append(Claim(agent=self.agent, group=self.group, item=item, released=True))
        return out

    def on_claim(self, claim: Claim) -> bool:
        """Take in another agent's claim or release; return whether it counts here."""
        if claim.group != self.group or claim.agent == self.agent:
            return False
        holders = self.held.setdefault(claim.item, {})
        if claim.released:
            holders.pop(claim.agent, None)
        else:
            holders[claim.agent] = min(claim.epoch, holders.get(claim.agent, claim.epoch))
        return True

    def owner(self, item: str) -> str | None:
        """Return the agent whose claim on `item` came first (None: nobody claims it)."""
        holders = self.held.get(item)
        if not holders:
            return None
        return min(holders.items(), key=lambda kv: (kv[1], kv[0]))[0]

    def foreign(self, atom: tuple[str, ...]) -> str | None:
        """Return the other agent that owns `atom`'s item, or None if it is free or ours."""
        item = self.claimable(atom)
        if item is None:
            return None
        owner = self.owner(item)
        return owner if owner not in (None, self.agent) else None

    def mine(self) -> list[Claim]:
        """This agent's standing claims (sent again when a new agent appears)."""
        return [
            Claim(agent=self.agent, group=self.group, item=item, epoch=holders[self.agent])
            for item, holders in sorted(self.held.items())
            if self.agent in holders
        ]
