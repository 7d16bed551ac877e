"""Claims: how agents of one group avoid pursuing the same goal object (pure logic).

An agent file lists claimable goal predicates (`[scheduler] claim = ["delivered"]`). When
a desire's goal holds an atom of one (`(delivered p1)`), the agent claims its first
argument (the item) in its group: it tells every agent of the group, who tell it of
theirs. Every agent computes the same assignment from the same claims, with no further
round of messages: only claims made within `WINDOW` epochs of an item's first claim
compete for it (agents that saw it at about the same time; a later claim never takes
an item over); items are assigned in order of their earliest claim, then their
cheapest claim (`cost`: the claimer's path length to it), and each goes to the claimer
with the lowest cost plus `LOAD_COST` for every item it already got (so one robot near
all the items does not get all of them), ties to the first name. An agent that holds an
item claims it again with cost `IN_HAND` (negative), and a holder owns its item whatever
the other claims say.

A later claim is a bid: an agent that owns no item and wants one another owns bids when
it can do it clearly sooner (`sooner`: its cost, against the owner's last told cost plus
`LOAD_COST` for each other item the owner has, by at least `HANDOVER` and
`HANDOVER_SHARE` of the owner's), and bids again only once its cost fell by `HANDOVER`
more. The owner alone decides, from its cost now: it hands the item over
(a release `to` the bidder; every agent then keeps only the bidder's claim on it) or
declines. One decider and a margin: the team does not churn. A bid never joins the
contest of an item's first claims (it is made later than `WINDOW` after them). An agent strips the
atoms of items others own from its desires, and drops a desire left with no goal. A
claim is released when the agent gives the atom up (its desire dropped), so another
agent may take the item, and when the atom is achieved: the release says so
(`achieved`), the group believes the atom and every claim on the item ends, so work
that comes back (the atom false again) is claimed afresh by whoever is nearer then.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

from cbdi.wire.agent import Claim

__all__ = ["HANDOVER", "HANDOVER_SHARE", "IN_HAND", "LOAD_COST", "WINDOW", "Claims", "sooner"]

LOAD_COST = 5.0  # what one more item in hand weighs against a longer way to the next
WINDOW = 5  # epochs: claims this close to an item's first claim compete for it
IN_HAND = -1.0  # the cost of a claim on an item in hand
HANDOVER = 3.0  # a bid wins an item over by at least this much less cost ...
HANDOVER_SHARE = 0.2  # ... and by at least this share of the owner's


def sooner(bid: float, owner: float) -> bool:
    """Return whether a bidder's cost `bid` is clearly below the owner's `owner`."""
    return bid + max(HANDOVER, HANDOVER_SHARE * owner) < owner


@dataclass
class Claims:
    """This agent's view of the claims in its group."""

    agent: str
    group: str
    predicates: frozenset[str]
    held: dict[str, dict[str, tuple[int, float]]] = field(default_factory=dict)
    # item -> agent -> (epoch, cost) of its claim
    _owners: dict[str, str] | None = field(default=None, repr=False, compare=False)
    # the assignment of `held`, until a claim changes it

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
        in_hand: Iterable[str] = (),
    ) -> list[Claim]:
        """Claim the items of `atoms` not claimed by this agent yet, and again those it now
        holds (cost IN_HAND); return the messages."""
        held = set(in_hand)
        out = []
        for atom in atoms:
            item = self.claimable(atom)
            if item is None:
                continue
            before = self.held.get(item, {}).get(self.agent)
            if before is not None and (before[1] < 0 or item not in held):
                continue
            c = IN_HAND if item in held else float(cost(item))
            at = before[0] if before is not None else epoch
            self.held.setdefault(item, {})[self.agent] = (at, c)
            self._owners = None
            out.append(Claim(agent=self.agent, group=self.group, item=item, epoch=at, cost=c))
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

    def bid(self, atom: tuple[str, ...], epoch: int, costs: Callable[[str], float]) -> list[Claim]:
        """Bid for the item of `atom`, which another agent owns, if this agent can do it
        clearly sooner (and sooner by `HANDOVER` than its last bid); return the message."""
        item = self.claimable(atom)
        owner = self.owner(item) if item is not None else None
        if item is None or owner is None or owner == self.agent or self.owned():
            return []  # only an agent with no work of its own bids (a guess of busy
            # agents' times against each other moved work back and forth for nothing)
        holders = self.held[item]
        told = holders[owner][1]
        first = min(e for e, _ in holders.values())
        if told < 0 or epoch <= first + WINDOW:
            return []  # held in hand, or the contest of its first claims still open
        cost = float(costs(item))
        last = holders.get(self.agent)
        if last is not None and last[1] - cost < HANDOVER:
            return []  # no better than our bid already told
        if not sooner(self.eta(self.agent, item, cost), self.eta(owner, item, told)):
            return []
        holders[self.agent] = (epoch, cost)
        self._owners = None
        return [Claim(agent=self.agent, group=self.group, item=item, epoch=epoch, cost=cost)]

    def answer(self, bid: Claim, cost: float, in_hand: Iterable[str] = ()) -> list[Claim]:
        """As the owner of `bid`'s item, whose cost of it is `cost` now: hand the item over
        to a bidder that can do it clearly sooner; return the handover (none: declined,
        or the item is not ours to give, or in hand, or the bid is one of the first
        claims, which compete as such)."""
        item = bid.item
        holders = self.held.get(item, {})
        mine, theirs = holders.get(self.agent), holders.get(bid.agent)
        first = min((epoch for epoch, _ in holders.values()), default=bid.epoch)
        if (
            bid.released
            or bid.epoch <= first + WINDOW  # made about the same time: the contest decides
            or mine is None
            or theirs is None
            or self.owner(item) != self.agent
            or mine[1] < 0
            or item in set(in_hand)
        ):
            return []
        if sooner(self.eta(bid.agent, item, theirs[1]), self.eta(self.agent, item, cost)):
            return [self._hand_over(item, bid.agent, theirs)]
        return []  # declined: the bidder bids again only once nearer by HANDOVER

    def _hand_over(self, item: str, to: str, bid: tuple[int, float]) -> Claim:
        self.held[item] = {to: bid}
        self._owners = None
        return Claim(
            agent=self.agent,
            group=self.group,
            item=item,
            released=True,
            to=to,
            epoch=bid[0],
            cost=bid[1],
        )

    def eta(self, agent: str, item: str, cost: float) -> float:
        """What `item` costs `agent` with its load: `cost` plus `LOAD_COST` for each other
        item the agent owns."""
        others = sum(1 for i, a in self.assignment().items() if a == agent and i != item)
        return cost + LOAD_COST * others

    def unpursued(self, items: Iterable[str]) -> list[Claim]:
        """Give up `items`, which this agent owns but pursues in no desire (a bid won
        after the rules stopped wanting it: kept, nobody would do it); return the
        messages."""
        out = []
        for item in sorted(set(items) & self.owned()):
            del self.held[item][self.agent]
            out.append(Claim(agent=self.agent, group=self.group, item=item, released=True))
        self._owners = None if out else self._owners
        return out

    def on_claim(self, claim: Claim) -> bool:
        """Take in another agent's claim or release; return whether it counts here."""
        if claim.group != self.group or claim.agent == self.agent:
            return False
        if claim.achieved and self.claimable(tuple(claim.achieved)) != claim.item:
            return False  # not a goal this group shares out
        holders = self.held.setdefault(claim.item, {})
        self._owners = None
        if claim.to:  # handed over: the bidder's claim alone stands
            self.held[claim.item] = {claim.to: (claim.epoch, claim.cost)}
        elif claim.achieved:  # the contest is over: every claim on the item ends, ours too
            del self.held[claim.item]
        elif claim.released:
            holders.pop(claim.agent, None)
        else:
            holders[claim.agent] = (claim.epoch, claim.cost)
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
            if not holders:
                continue
            first = min(epoch for epoch, _ in holders.values())
            bids = {a: cost for a, (epoch, cost) in holders.items() if epoch <= first + WINDOW}
            bids.update({a: cost for a, (_, cost) in holders.items() if cost < 0})
            contests.append((first, min(bids.values()), item, bids))
        load: dict[str, int] = {}
        owners = {}
        for _, _, item, bids in sorted(contests, key=lambda c: c[:3]):
            holder = [a for a, cost in bids.items() if cost < 0]
            winner = min(holder or bids, key=lambda a: (bids[a] + LOAD_COST * load.get(a, 0), a))
            owners[item] = winner
            load[winner] = load.get(winner, 0) + 1
        return owners

    def owned(self) -> set[str]:
        """The items this agent owns."""
        return {item for item, owner in self.assignment().items() if owner == self.agent}

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
            Claim(
                agent=self.agent,
                group=self.group,
                item=item,
                epoch=holders[self.agent][0],
                cost=holders[self.agent][1],
            )
            for item, holders in sorted(self.held.items())
            if self.agent in holders
        ]
