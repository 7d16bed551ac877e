"""Claims: how agents of one group share out goal objects (pure logic).

An agent file lists claimable goal predicates (`[scheduler] claim = ["delivered"]`). When
a desire's goal holds an atom of one (`(delivered p1)`), the agent claims its first
argument (the item) in its group: it tells every agent of the group, who tell it of
theirs. Every agent computes the same assignment from the same claims, with no further
round of messages:

1. **Holding.** An agent that holds an item claims it with cost `HOLDING` (negative) and
   owns it, whatever the other claims say.
2. **Cost, load, margin.** Otherwise every standing claim on an item competes by its
   score. A claim on an item the claimer already pursues (it has had it in its goal
   since an epoch before: `pursuing`) scores its cost less a margin,
   `max(TAKEOVER, TAKEOVER_SHARE * cost)`; any other claim scores its cost plus
   `LOAD_COST` for every item the assignment already gave the claimer (so one robot near
   all the items does not get all of them). So a robot on its way keeps its item unless
   another, its load counted, can do it clearly sooner (hysteresis: the team does not
   churn), and a pursuer's other items never count against it. Items are assigned in
   order of their earliest claim, then their cheapest claim, then name; the lowest score
   wins, ties to the earlier claim, then to the first name.
3. **Fresh costs.** An agent sends its claim again when its cost changed by `REFRESH` or
   more, or it began or stopped pursuing or holding the item. A cost the agent does not
   know (`UNKNOWN` or more: no believed way) is sent only in a first claim (as
   `UNKNOWN`): a claim standing keeps the last known cost, since a way believed blocked
   for a moment must not hand the item over and back (a plan that truly fails gives the
   claim back, rule 5).
4. **Bids.** An agent whose rules want an item another owns claims it only when that
   claim would win the item now (`would_win`, with the owner's standing claim), and
   withdraws a claim that lost once its contest has settled (an epoch after it was
   made): so losers do not keep a claim per item wanted.
5. **Ends.** A claim ends when the agent gives its atom up (its desire dropped: a
   failed plan, a deadline) and when the atom is achieved: then the release says so, the
   group believes the atom and every claim on the item ends, so that the item, if its
   goal becomes false again (work that comes back), is claimed afresh by whoever is
   nearer then.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Iterable
from dataclasses import dataclass, field
from typing import NamedTuple

from cbdi.wire.agent import Claim

__all__ = [
    "HOLDING",
    "LOAD_COST",
    "REFRESH",
    "TAKEOVER",
    "TAKEOVER_SHARE",
    "UNKNOWN",
    "Claims",
    "Held",
    "margin",
]

LOAD_COST = 5.0  # what one more item in hand weighs against a longer way to the next
HOLDING = -1.0  # the cost of a claim on an item in hand
TAKEOVER = 5.0  # a pursuer's margin: another must be this much cheaper to take over...
TAKEOVER_SHARE = 0.25  # ...or this share of the pursuer's cost, whichever is more
REFRESH = 2.0  # a claim is sent again when its cost changed by this much
UNKNOWN = 1e6  # a cost from this up: the claimer knows no way to the item


def margin(cost: float) -> float:
    """What a pursuer's claim counts less than its cost."""
    return max(TAKEOVER, TAKEOVER_SHARE * cost)


class Held(NamedTuple):
    """One agent's standing claim on an item."""

    epoch: int
    cost: float
    pursuing: bool = False


_NONE = Held(2**62, 0.0)  # no claim: never settled


@dataclass
class Claims:
    """This agent's view of the claims in its group."""

    agent: str
    group: str
    predicates: frozenset[str]
    held: dict[str, dict[str, Held]] = field(default_factory=dict)  # item -> agent -> claim
    # the assignment of `held`, until a claim changes it
    _owners: dict[str, str] | None = field(default=None, repr=False, compare=False)

    def claimable(self, atom: tuple[str, ...]) -> str | None:
        """Return the item `atom` claims, or None if its predicate is not claimable."""
        if atom[0] in self.predicates and len(atom) > 1:
            return atom[1]
        return None

    def claim(
        self,
        atoms: Iterable[tuple[str, ...]],
        epoch: int,
        cost: Callable[[str], float] = lambda item: 0.0,
        holding: Collection[str] = (),
        pursuing: Collection[str] = (),
    ) -> list[Claim]:
        """Claim the items of `atoms` (those in `pursuing` as pursued, those in `holding`
        at cost HOLDING); send a claim made before again only if it changed enough.
        Return the messages."""
        out = []
        for atom in atoms:
            item = self.claimable(atom)
            if item is None:
                continue
            before = self.held.get(item, {}).get(self.agent)
            c = HOLDING if item in holding else _known(float(cost(item)))
            if c == UNKNOWN and before is not None and before.cost >= 0:
                c = before.cost  # keep the last known cost (rule 3)
            now = Held(before.epoch if before is not None else epoch, c, item in pursuing)
            if before is not None and not _changed(before, now):
                continue
            self.held.setdefault(item, {})[self.agent] = now
            self._owners = None
            out.append(self._message(item, now))
        return out

    def release(self, atoms: Iterable[tuple[str, ...]], achieved: bool = False) -> list[Claim]:
        """Give up this agent's claims on the items of `atoms` (`achieved`: because the
        atoms hold now; the messages say so); return the messages."""
        out = []
        for atom in atoms:
            item = self.claimable(atom)
            if item is None or self.held.get(item, {}).pop(self.agent, None) is None:
                continue
            self._owners = None
            if achieved:  # the contest is over: every claim on the item ends
                self.held.pop(item, None)
            done = list(atom) if achieved else []
            out.append(
                Claim(agent=self.agent, group=self.group, item=item, released=True, achieved=done)
            )
        return out

    def on_claim(self, claim: Claim) -> bool:
        """Take in another agent's claim or release; return whether it counts here."""
        if claim.group != self.group or claim.agent == self.agent:
            return False
        if claim.achieved and self.claimable(tuple(claim.achieved)) != claim.item:
            return False  # not a goal this group shares out
        holders = self.held.setdefault(claim.item, {})
        self._owners = None
        if claim.achieved:  # the contest is over: every claim on the item ends, ours too
            del self.held[claim.item]
        elif claim.released:
            holders.pop(claim.agent, None)
        else:
            holders[claim.agent] = Held(claim.epoch, claim.cost, claim.pursuing)
        return True

    def owner(self, item: str) -> str | None:
        """Return the agent `item` is assigned to (None: nobody claims it)."""
        return self.assignment().get(item)

    def assignment(self) -> dict[str, str]:
        """Return every claimed item's owner (the same at every agent with these claims)."""
        if self._owners is None:
            self._owners = self._assign()
        return self._owners

    def _assign(self) -> dict[str, str]:
        contests = []
        for item, holders in self.held.items():
            if holders:
                first = min(h.epoch for h in holders.values())
                contests.append((first, min(h.cost for h in holders.values()), item, holders))
        load: dict[str, int] = {}
        owners = {}
        for _, _, item, holders in sorted(contests, key=lambda c: c[:3]):
            holding = [a for a, h in holders.items() if h.cost < 0]

            def score(a: str, holders: dict[str, Held] = holders) -> tuple[float, int, str]:
                h = holders[a]
                if h.pursuing:
                    return (h.cost - margin(h.cost), h.epoch, a)
                return (h.cost + LOAD_COST * load.get(a, 0), h.epoch, a)

            winner = min(holding) if holding else min(holders, key=score)
            owners[item] = winner
            load[winner] = load.get(winner, 0) + 1
        return owners

    def settled(self, epoch: int) -> set[str]:
        """The items this agent claimed before `epoch`: their contest has settled (every
        claim of the epoch it began is in), so if they are ours we pursue them."""
        return {
            i for i, holders in self.held.items() if holders.get(self.agent, _NONE).epoch < epoch
        }

    def standing(self, item: str) -> bool:
        """Tell whether this agent has a claim on `item`."""
        return self.agent in self.held.get(item, {})

    def would_win(self, item: str, epoch: int, cost: float) -> bool:
        """Tell whether a claim of ours on `item` at `cost` (not pursuing) would own it;
        an unknown cost never would."""
        if _known(cost) == UNKNOWN:
            return False
        holders = self.held.setdefault(item, {})
        before = holders.get(self.agent)
        holders[self.agent] = Held(before.epoch if before is not None else epoch, cost)
        try:
            return self._assign().get(item) == self.agent
        finally:
            if before is None:
                del holders[self.agent]
            else:
                holders[self.agent] = before

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
            self._message(item, holders[self.agent])
            for item, holders in sorted(self.held.items())
            if self.agent in holders
        ]

    def _message(self, item: str, h: Held) -> Claim:
        return Claim(
            agent=self.agent,
            group=self.group,
            item=item,
            epoch=h.epoch,
            cost=h.cost,
            pursuing=h.pursuing,
        )


def _known(cost: float) -> float:
    """`cost`, or UNKNOWN for any cost from UNKNOWN up (infinite and NaN too)."""
    return cost if cost < UNKNOWN else UNKNOWN


def _changed(before: Held, now: Held) -> bool:
    """Whether a claim must be sent again: it began or stopped holding or pursuing, or
    its cost moved by REFRESH or more."""
    if (before.cost < 0) != (now.cost < 0) or before.pursuing != now.pursuing:
        return True
    return now.cost >= 0 and abs(now.cost - before.cost) >= REFRESH
