"""The agent's mind: the BDI cycle as one pure object, fed by events, giving commands.

On every percept: revise beliefs (Events Monitor), fire the reactive rules (on the
events sensed since the last cycle too, which are never standing beliefs), drop desires
whose deadline passed or whose context failed, notice an achieved intention, and let the
goal reasoner choose what to pursue; the intention scheduler turns that into commands.
Plans, search failures, step statuses and arrest reports go to the intention scheduler.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from cbdi.beliefs import FUNCTION, Belief, BeliefSet, fact
from cbdi.wire.agent import ActionStatus, ArrestReport, Claim, DesireEvent, PartialPlan
from cbdi.wire.world import (
    ActionOutcome,
    Percept,
)
from cbdi_scheduler.agentfile import AgentFile
from cbdi_scheduler.claims import Claims
from cbdi_scheduler.desires import Desire, Drop, achieved, drops, joint, select_desire
from cbdi_scheduler.intentions import Command, Intention, IntentionScheduler
from cbdi_scheduler.knowledge import DomainKnowledge, load_knowledge
from cbdi_scheduler.rules import Ask, fire_rules

__all__ = ["MAX_EVENTS", "Mind", "Reaction"]

MAX_EVENTS = 10_000  # distinct events told between two cycles that the next one sees


@dataclass
class Reaction:
    """What the mind decided after one event."""

    commands: list[Command] = field(default_factory=list)
    events: list[DesireEvent] = field(default_factory=list)
    beliefs_changed: bool = False
    claims: list[Claim] = field(default_factory=list)  # to tell the group
    asks: list[Ask] = field(default_factory=list)  # to send to other agents of the group


class Mind:
    """One agent's beliefs, desires and intentions."""

    def __init__(self, spec: AgentFile, knowledge: DomainKnowledge | None = None) -> None:
        self.spec = spec
        self.knowledge = knowledge or load_knowledge(spec.knowledge, spec.agent, spec.source)
        self.agent = spec.agent
        self.beliefs = BeliefSet.of(spec.beliefs)
        self.desires: dict[str, Desire] = {d.name: d for d in spec.desires}
        self.intentions = IntentionScheduler(
            spec.preemption,
            spec.plan_retries,
            spec.exec_retries,
            spec.wait_stall,
            spread=spec.wait_stall_spread,
            agent=spec.agent,
            stall_counts=spec.wait_stall_counts,
        )
        self.now = 0.0
        self.epoch = -1
        self.refire = False  # fire the rules next cycle even if nothing changed
        # What requests changed between cycles: events to publish, desires to withdraw.
        self.requested: list[DesireEvent] = []
        self.withdrawn: dict[str, str] = {}  # desire -> reason
        self.stop_asked: bool | None = None  # a safe stop (True) or a resume (False) asked
        self.halted_at = 0.0  # when the safe stop began: deadlines wait meanwhile
        self.claims = Claims(self.agent, spec.group, frozenset(spec.claim)) if spec.claim else None
        # The beliefs changed between cycles (an outcome, a sensor, an operator): the next
        # cycle counts it as a change, so a failed search waiting for one is retried.
        self.changed = False
        self.asking: frozenset[Ask] = frozenset()  # the asks the rules made last time
        self.events: list[Belief] = []  # told since the last cycle, for its rules only

    def event(self, desire: Desire, event: str, reason: str = "") -> DesireEvent:
        return DesireEvent(
            agent=self.agent,
            desire=desire.name,
            event=event,
            reason=reason,
            time=self.now,
            goal=[list(g.atom) for g in desire.goal],
        )

    def on_percepts(self, p: Percept) -> Reaction:
        """Run one BDI cycle on this epoch's percepts."""
        self.now, self.epoch = p.time, p.epoch
        before = self.beliefs
        self.beliefs = self.knowledge.on_percepts(self.beliefs, p)
        out = Reaction(beliefs_changed=self.beliefs != before)
        changed, self.changed = self.changed or out.beliefs_changed, False
        if changed:  # a search under way may have started from the beliefs before
            self.intentions.changed_meanwhile = True
        out.events += self.requested
        self.requested = []
        events, self.events = self.events, []
        if out.beliefs_changed or self.epoch == 0 or self.refire or events or self._unpursued():
            # After a drop the rules fire again even on unchanged beliefs: what made the
            # desire (an object still waiting there) may well make it again.
            self.refire = False
            self._fire(out, events)
            if self.claims is not None:  # given back: what we own and no desire pursues
                out.claims += self.claims.unpursued(self._unpursued())
        self._coordinate(out)
        self._stop_or_resume(out)
        self._deliberate(out)
        if changed or self.intentions.retry_due:
            out.commands += self.intentions.retry(self.now)
        else:
            stalled = self._with_drops(self.intentions.stalled(self.now))
            out.commands += stalled.commands
            out.events += stalled.events
            out.claims += stalled.claims
        self._believe_stalled()
        return out

    # -- requests (another agent, an operator) -------------------------------------------
    def request_desire(self, desire: Desire) -> None:
        """Hold `desire` from now (a request); the next cycle may pursue it."""
        self.desires[desire.name] = desire
        self.requested.append(self.event(desire, "added"))

    def withdraw(self, name: str, reason: str) -> None:
        """Drop desire `name` at the next cycle (a request), stopping its intention."""
        self.withdrawn[name] = reason

    def request_stop(self, stop: bool) -> None:
        """Stop safely (or resume) at the next cycle (a request)."""
        self.stop_asked = stop

    def _stop_or_resume(self, out: Reaction) -> None:
        asked, self.stop_asked = self.stop_asked, None
        intentions = self.intentions
        if asked is None or asked == intentions.halted:
            return
        cur = intentions.current
        if asked:
            self.halted_at = self.now
            out.commands += intentions.halt()
        else:
            # The agent's time stood still: every deadline moves on by the stop's length.
            paused = self.now - self.halted_at
            self.desires = {n: _postponed(d, paused) for n, d in self.desires.items()}
            if cur is not None:
                cur.desire = _postponed(cur.desire, paused)
            out.commands += intentions.resume(self.now)
        if cur is not None:
            out.events.append(self.event(cur.desire, "halted" if asked else "resumed"))

    def request_beliefs(
        self, add: list[Belief], remove: list[Belief], threshold: float = 0.0
    ) -> None:
        """Believe `add` and stop believing `remove` (a request); the rules fire again.

        A function value in `add` within `threshold` of the value believed is no change
        (a sensor's noise): it is not taken, and a request of nothing else neither fires
        the rules nor retries a failed search.
        """
        add = [b for b in add if not self._within(b, threshold)]
        if not add and not remove:
            return
        before = self.beliefs
        self.beliefs = self.beliefs.removing(remove).adding(add)
        self.refire = True
        self.changed = self.changed or self.beliefs != before

    def _within(self, belief: Belief, threshold: float) -> bool:
        if belief.kind != FUNCTION:
            return False
        held = self.beliefs.fluents.get(belief.atom)
        return held is not None and abs(belief.value - held) <= threshold

    def request_event(self, event: Belief) -> None:
        """Let the rules of the next cycle see `event`, a predicate atom, as a belief; it
        is not believed before or after (the planner never sees it). Events of one atom
        told between two cycles are one."""
        if event not in self.events:
            self.events.append(event)
            del self.events[:-MAX_EVENTS]  # no cycle for long (no world): keep the latest

    def _believe_stalled(self) -> None:
        """Believe `(stalled DESIRE)` while the intention's blocked wait is stalled, so a
        rule can make the robot yield (step aside); the rules see it next cycle."""
        cur = self.intentions.current
        want = {("stalled", cur.desire.name)} if cur is not None and cur.stalled else set()
        have = set(self.beliefs.facts_of("stalled"))
        if want == have:
            return
        self.beliefs = self.beliefs.removing(fact(*f) for f in have - want).adding(
            fact(*f) for f in want - have
        )
        self.refire = True

    def _fire(self, out: Reaction, events: list[Belief]) -> None:
        """Fire the rules on the beliefs and this cycle's `events`; then forget the
        events (one believed anyway stays: it is a standing belief too)."""
        passing = [e for e in events if not self.beliefs.holds(e)]
        seen = self.beliefs.adding(passing) if passing else self.beliefs
        fired = fire_rules(self.spec.rules, seen, self.desires, self.now)
        desires = self._unclaimed(fired.desires, out)
        added = [d for n, d in desires.items() if n not in self.desires]
        boosted = [n for n in fired.boosted if n in desires and desires[n] != self.desires.get(n)]
        beliefs = fired.beliefs.removing(passing) if passing else fired.beliefs
        self.beliefs, self.desires = beliefs, desires
        out.events += [self.event(d, "added") for d in added]
        out.events += [self.event(self.desires[n], "boosted") for n in boosted]
        # An ask goes once, when its rule starts to match: not again while it matches.
        out.asks += [a for a in fired.asks if a not in self.asking and a.agent != self.agent]
        self.asking = frozenset(fired.asks)

    def _unclaimed(self, desires: dict[str, Desire], reaction: Reaction) -> dict[str, Desire]:
        """Leave out what rules just added to our desires that another agent owns; bid
        for those we could do clearly sooner (`Claims.bid`)."""
        claims = self.claims
        if claims is None:
            return desires
        out = {}
        in_hand = self._in_hand()
        for name, d in desires.items():
            held = self.desires.get(name)
            old = set(held.goal) if held is not None else set()
            for g in d.goal:
                if g not in old and not self.beliefs.holds(g) and not self._ours(g.atom, in_hand):
                    reaction.claims += claims.bid(g.atom, self.epoch, self._cost)
            goal = tuple(g for g in d.goal if g in old or self._takes(g, in_hand))
            if held is not None and set(goal) == old:
                out[name] = held  # what a boost brought was all others': nothing new
            elif goal:
                out[name] = replace(d, goal=goal) if goal != d.goal else d
        return out

    def _deliberate(self, out: Reaction) -> None:
        current = self.intentions.current
        if current is not None and achieved(current.desire, self.beliefs):
            out.commands += self.intentions.achieved()
            for name in self._members(current.desire):  # each its own event
                out.events.append(self.event(self.desires.pop(name), "achieved"))
            out.events.append(self.event(current.desire, "achieved"))
            self.desires.pop(current.desire.name, None)
        cur = self.intentions.current
        active = set(self._members(cur.desire)) | {cur.desire.name} if cur else set()
        executing = cur is not None and bool(cur.plan_id)
        rtc = self.spec.rtc_deadline
        asked, self.withdrawn = self.withdrawn, {}
        dropping = [Drop(n, why) for n, why in sorted(asked.items()) if n in self.desires]
        if not self.intentions.halted:  # a stopped agent's deadlines wait
            dropping += [
                d
                for d in drops(self.desires, self.beliefs, self.now, active, executing, rtc)
                if d.desire not in asked
            ]
        for drop in dropping:
            desire = self.desires.pop(drop.desire)
            self._dropped(desire, drop.reason, out)
            if drop.desire in active and self.intentions.current is not None:
                out.commands += self.intentions.drop(drop.reason)  # a joint one: all of it
        for name, d in list(self.desires.items()):
            if achieved(d, self.beliefs) and (cur is None or name != cur.desire.name):
                out.events.append(self.event(self.desires.pop(name), "achieved"))
        chosen = select_desire(self.desires, self.beliefs, self.now)
        if chosen is not None:
            pursued = self.intentions.current.desire if self.intentions.current else None
            chosen = joint(chosen, self.desires, self.beliefs, self.now, pursued)
        before = self.intentions.current
        out.commands += self.intentions.choose(chosen)
        after = self.intentions.current
        if after is not None and (before is None or before.desire.name != after.desire.name):
            out.events.append(self.event(after.desire, "activated"))

    def on_outcome(self, outcome: ActionOutcome) -> Reaction:
        """Revise beliefs with what an action's outcome tells (the next cycle reacts)."""
        if outcome.agent != self.agent:
            return Reaction()
        before = self.beliefs
        self.beliefs = self.knowledge.on_outcome(self.beliefs, outcome)
        changed = self.beliefs != before
        self.changed = self.changed or changed
        return Reaction(beliefs_changed=changed)

    # -- planner and executor ------------------------------------------------------------
    def on_plan(self, plan: PartialPlan) -> Reaction:
        return Reaction(self.intentions.on_plan(plan))

    def on_search_failed(self, reason: str, blocked: bool = False) -> Reaction:
        return self._with_drops(self.intentions.on_search_failed(reason, blocked, self.now))

    def on_status(self, status: ActionStatus) -> Reaction:
        return self._with_drops(self.intentions.on_status(status))

    def on_arrested(self, report: ArrestReport) -> Reaction:
        before = self.intentions.current
        out = Reaction(self.intentions.on_arrested(report))
        after = self.intentions.current
        if after is not None and (before is None or before.desire.name != after.desire.name):
            out.events.append(self.event(after.desire, "activated"))  # a clean preemption
        return out

    def _members(self, desire: Desire | Intention | None) -> set[str]:
        """The names of the desires a joint intention's desire pursues (none otherwise)."""
        if isinstance(desire, Intention):
            desire = desire.desire
        if desire is None or not desire.is_joint:
            return set()
        return {n for n, d in self.desires.items() if desire.member(d)}

    def _with_drops(self, commands: list[Command]) -> Reaction:
        out = Reaction(commands)
        for c in commands:
            if c.kind == "drop" and c.desire is not None:
                for name in sorted(self._members(c.desire)):  # given up with it
                    self._dropped(self.desires.pop(name), c.reason, out)
                self.desires.pop(c.desire.name, None)
                self._dropped(c.desire, c.reason, out)
            elif c.kind == "wait" and c.desire is not None:
                out.events.append(self.event(c.desire, "waiting", c.reason))
        return out

    def _dropped(self, desire: Desire, reason: str, out: Reaction) -> None:
        out.events.append(self.event(desire, "dropped", reason))
        self.refire = True
        if self.claims is not None:  # others may take up what we gave up (not held)
            held = self._in_hand()
            out.claims += self.claims.release(
                g.atom for g in desire.goal if self.claims.claimable(g.atom) not in held
            )

    def _ours(self, atom: tuple[str, ...], in_hand: set[str]) -> bool:
        """Return whether `atom`'s object is free or ours: an item in hand is always ours
        (we claim it as its holder), even if another agent's claim won it before."""
        assert self.claims is not None
        return self.claims.foreign(atom) is None or self.claims.claimable(atom) in in_hand

    def _takes(self, goal: Belief, in_hand: set[str]) -> bool:
        """Return whether a rule's new goal atom is ours to take up: its object is free
        or ours, and a shared goal is not already achieved (by us or, as the group told,
        by another agent)."""
        assert self.claims is not None
        if self.claims.claimable(goal.atom) is not None and self.beliefs.holds(goal):
            return False
        return self._ours(goal.atom, in_hand)

    def _in_hand(self) -> set[str]:
        return self.knowledge.in_hand(self.beliefs, self.agent)

    def _cost(self, item: str) -> float:
        return self.knowledge.cost(self.beliefs, self.agent, item)

    def _unpursued(self) -> set[str]:
        """The items we own that no desire pursues and we do not hold."""
        if self.claims is None:
            return set()
        owned = self.claims.owned() - self._in_hand()
        if not owned:
            return owned
        atoms = (g.atom for d in self.desires.values() for g in d.goal)
        return owned - {self.claims.claimable(a) for a in atoms}

    # -- claims in the group -------------------------------------------------------------
    def on_claim(self, claim: Claim) -> Reaction:
        """Another agent of the group claimed (or released) a goal object: take it in
        (and answer a bid); the next cycle weighs the claims, all that came by then at
        once, so that a view of some of them (a contest half heard) drops nothing."""
        out = Reaction()
        if self.claims is None:
            return out
        had = self.claims.owned()
        if not self.claims.on_claim(claim):
            return out
        # The rules may take an item up now: given up, or a contest turned our way.
        self.refire = self.refire or claim.released or not self.claims.owned() <= had
        if not claim.released and self.claims.owner(claim.item) == self.agent:  # a bid
            out.claims += self.claims.answer(claim, self._cost(claim.item), self._in_hand())
        if claim.achieved:  # the claimer achieved the goal atom: the group believes it
            before = self.beliefs
            self.beliefs = self.beliefs.adding([fact(*claim.achieved)])
            self.changed = self.changed or self.beliefs != before
        return out

    def _coordinate(self, out: Reaction) -> None:
        """Claim the objects of our goals; leave those another agent owns."""
        claims = self.claims
        if claims is None:
            return
        in_hand = self._in_hand()
        for name, desire in list(self.desires.items()):
            mine = [g for g in desire.goal if self._ours(g.atom, in_hand)]
            # A claim ends when its goal atom is achieved: the item is free to be
            # claimed anew if the atom becomes false again (work that comes back).
            done = [g.atom for g in mine if self.beliefs.holds(g)]
            out.claims += claims.release(done, achieved=True)
            out.claims += claims.claim(
                (g.atom for g in mine if not self.beliefs.holds(g)),
                self.epoch,
                self._cost,
                in_hand=in_hand,
            )
            if len(mine) == len(desire.goal):
                continue
            left = [g.atom for g in desire.goal if g not in mine]
            owners = sorted({f"{' '.join(a)} by {claims.foreign(a)}" for a in left})
            if mine:
                self.desires[name] = replace(desire, goal=tuple(mine))
                reason = "claimed by others: " + ", ".join(owners)
                out.events.append(self.event(self.desires[name], "reduced", reason))
                # Our claims on what we lost end, as a dropped desire's do: a contest
                # kept open by them turned with every item done elsewhere (the loads
                # changed), and two robots took a parcel from each other in turn.
                out.claims += claims.release(left)
                continue
            del self.desires[name]
            reason = "claimed by others: " + ", ".join(owners)
            self._dropped(desire, reason, out)
            if self.intentions.current is not None and self.intentions.current.desire.name == name:
                out.commands += self.intentions.drop(reason)


def _postponed(desire: Desire, seconds: float) -> Desire:
    return replace(desire, deadline=desire.deadline + seconds) if seconds > 0 else desire
