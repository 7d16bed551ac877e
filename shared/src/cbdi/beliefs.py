"""Beliefs: what an agent holds true, as typed PDDL: instances, predicates, functions.

Shared by the scheduler (which revises them), the executor (which checks actions against
them) and the planner (which plans from them).

A `BeliefSet` is immutable; every revision returns a new one, so a reasoner can compare
before and after (reactive rules fire on change) and nothing is shared by accident.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from types import MappingProxyType

from msgspec.structs import replace

from cbdi.wire.agent import BeliefsUpdate

__all__ = [
    "Atom",
    "Belief",
    "BeliefSet",
    "BeliefsReceiver",
    "BeliefsSender",
    "fact",
    "fluent",
    "from_wire",
    "instance",
    "to_wire",
]

Atom = tuple[str, ...]  # ("parcel_at", "p1", "c_6_1"): a predicate or function and its args

INSTANCE, PREDICATE, FUNCTION = "instance", "predicate", "function"


@dataclass(frozen=True)
class Belief:
    """One belief: an instance (`name` of `type`), a predicate atom, or a function value."""

    kind: str
    name: str
    params: tuple[str, ...] = ()
    type: str = ""
    value: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in (INSTANCE, PREDICATE, FUNCTION):
            raise ValueError(f"belief kind must be instance, predicate or function: {self.kind!r}")
        if not self.name:
            raise ValueError("a belief needs a name")

    @property
    def atom(self) -> Atom:
        return (self.name, *self.params)

    def __str__(self) -> str:
        if self.kind == INSTANCE:
            return f"{self.name} - {self.type}"
        text = f"({' '.join(self.atom)})"
        return f"{text} = {self.value:g}" if self.kind == FUNCTION else text


def instance(name: str, type_: str) -> Belief:
    return Belief(INSTANCE, name, type=type_)


def fact(name: str, *params: str) -> Belief:
    return Belief(PREDICATE, name, tuple(params))


def fluent(name: str, *params: str, value: float) -> Belief:
    return Belief(FUNCTION, name, tuple(params), value=value)


@dataclass(frozen=True)
class BeliefSet:
    """An immutable set of beliefs."""

    instances: Mapping[str, str] = field(default_factory=lambda: MappingProxyType({}))
    facts: frozenset[Atom] = frozenset()
    fluents: Mapping[Atom, float] = field(default_factory=lambda: MappingProxyType({}))

    @classmethod
    def of(cls, beliefs: Iterable[Belief]) -> BeliefSet:
        return cls().adding(beliefs)

    def adding(self, beliefs: Iterable[Belief]) -> BeliefSet:
        """Return these beliefs plus `beliefs` (a function belief sets the value)."""
        inst, facts, flu = dict(self.instances), set(self.facts), dict(self.fluents)
        for b in beliefs:
            if b.kind == INSTANCE:
                inst[b.name] = b.type
            elif b.kind == PREDICATE:
                facts.add(b.atom)
            else:
                flu[b.atom] = b.value
        return self._derived(inst, frozenset(facts), flu)

    def removing(self, beliefs: Iterable[Belief]) -> BeliefSet:
        """Return these beliefs without `beliefs`."""
        inst, facts, flu = dict(self.instances), set(self.facts), dict(self.fluents)
        for b in beliefs:
            if b.kind == INSTANCE:
                inst.pop(b.name, None)
            elif b.kind == PREDICATE:
                facts.discard(b.atom)
            else:
                flu.pop(b.atom, None)
        return self._derived(inst, frozenset(facts), flu)

    def _derived(
        self, inst: dict[str, str], facts: frozenset[Atom], flu: dict[Atom, float]
    ) -> BeliefSet:
        """A belief set changed from this one; it takes over this one's index of facts
        by predicate (if built), sorting again only the predicates that changed."""
        out = BeliefSet(MappingProxyType(inst), facts, MappingProxyType(flu))
        index = self.__dict__.get("_facts_by_predicate")
        if index is not None:
            changed: dict[str, set[Atom]] = {}
            for atom in facts ^ self.facts:  # each one added or removed
                changed.setdefault(atom[0], set()).add(atom)
            new = dict(index)
            for name, atoms in changed.items():
                group = sorted(set(index.get(name, ())) ^ atoms)
                if group:
                    new[name] = tuple(group)
                else:
                    new.pop(name, None)
            out.__dict__["_facts_by_predicate"] = new
        return out

    def facts_of(self, predicate: str) -> Sequence[Atom]:
        """Return the facts of `predicate`, sorted (indexed once per belief set)."""
        return self._facts_by_predicate.get(predicate, ())

    def fluents_of(self, function: str) -> Sequence[tuple[Atom, float]]:
        """Return the values of `function`, sorted by atom (indexed once per belief set)."""
        return self._fluents_by_function.get(function, ())

    @cached_property
    def sorted_instances(self) -> Sequence[tuple[str, str]]:
        """Every instance and its type, sorted by name."""
        return tuple(sorted(self.instances.items()))

    @cached_property
    def _facts_by_predicate(self) -> dict[str, tuple[Atom, ...]]:
        out: dict[str, list[Atom]] = {}
        for atom in sorted(self.facts):
            out.setdefault(atom[0], []).append(atom)
        return {k: tuple(v) for k, v in out.items()}

    @cached_property
    def _fluents_by_function(self) -> dict[str, tuple[tuple[Atom, float], ...]]:
        out: dict[str, list[tuple[Atom, float]]] = {}
        for atom, value in sorted(self.fluents.items()):
            out.setdefault(atom[0], []).append((atom, value))
        return {k: tuple(v) for k, v in out.items()}

    def holds(self, b: Belief) -> bool:
        """Return whether `b` is believed (a function belief: with that value)."""
        if b.kind == INSTANCE:
            return self.instances.get(b.name) == b.type
        if b.kind == PREDICATE:
            return b.atom in self.facts
        return self.fluents.get(b.atom) == b.value

    def beliefs(self) -> list[Belief]:
        """Return every belief, sorted (instances, then facts, then functions)."""
        out = [instance(n, t) for n, t in sorted(self.instances.items())]
        out += [Belief(PREDICATE, a[0], a[1:]) for a in sorted(self.facts)]
        out += [Belief(FUNCTION, a[0], a[1:], value=v) for a, v in sorted(self.fluents.items())]
        return out

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, BeliefSet):
            return NotImplemented
        if self is other:
            return True
        return (
            len(self.facts) == len(other.facts)
            and self.facts == other.facts
            and dict(self.instances) == dict(other.instances)
            and dict(self.fluents) == dict(other.fluents)
        )

    def __hash__(self) -> int:
        return hash(
            (frozenset(self.instances.items()), self.facts, frozenset(self.fluents.items()))
        )


def to_wire(beliefs: BeliefSet, agent: str, time: float, epoch: int = -1) -> BeliefsUpdate:
    """Return the message that publishes `beliefs`."""
    return BeliefsUpdate(
        agent=agent,
        time=time,
        epoch=epoch,
        instances=dict(beliefs.instances),
        facts=[list(a) for a in sorted(beliefs.facts)],
        fluents=[(list(a), v) for a, v in sorted(beliefs.fluents.items())],
    )


def from_wire(update: BeliefsUpdate) -> BeliefSet:
    """Return the belief set a whole-set `BeliefsUpdate` carries (a change needs the set
    it changes: `BeliefsReceiver`)."""
    if update.base:
        raise ValueError(f"beliefs update {update.seq} changes update {update.base}")
    return BeliefSet(
        MappingProxyType(dict(update.instances)),
        frozenset(tuple(f) for f in update.facts),
        MappingProxyType({tuple(a): float(v) for a, v in update.fluents}),
    )


class BeliefsSender:
    """Number a series of belief sets and send each as what changed since the last one.

    A whole set goes first, then every `whole_every` updates, and next after `resend()`
    (a receiver appeared that may have missed the series): a receiver that lost its place
    is back within that many updates.
    """

    def __init__(self, agent: str, whole_every: int = 64) -> None:
        if whole_every < 1:
            raise ValueError("whole_every must be at least 1")
        self.agent, self.whole_every = agent, whole_every
        self.seq = 0
        self.last: BeliefSet | None = None
        self.since_whole = 0

    def resend(self) -> None:
        """Send the next update whole."""
        self.last = None

    def update(self, beliefs: BeliefSet, time: float, epoch: int = -1) -> BeliefsUpdate:
        """Return the next update of the series, for `beliefs`."""
        self.seq += 1
        last, self.last = self.last, beliefs
        if last is None or self.since_whole + 1 >= self.whole_every:
            self.since_whole = 0
            return replace(to_wire(beliefs, self.agent, time, epoch), seq=self.seq)
        self.since_whole += 1
        inst, old_inst = beliefs.instances, last.instances
        flu, old_flu = beliefs.fluents, last.fluents
        return BeliefsUpdate(
            agent=self.agent,
            time=time,
            epoch=epoch,
            seq=self.seq,
            base=self.seq - 1,
            instances={n: t for n, t in sorted(inst.items()) if old_inst.get(n) != t},
            facts=[list(a) for a in sorted(beliefs.facts - last.facts)],
            fluents=[(list(a), v) for a, v in sorted(flu.items()) if old_flu.get(a) != v],
            dropped_instances=sorted(n for n in old_inst if n not in inst),
            dropped_facts=[list(a) for a in sorted(last.facts - beliefs.facts)],
            dropped_fluents=[list(a) for a in sorted(a for a in old_flu if a not in flu)],
        )


class BeliefsReceiver:
    """Rebuild a sender's belief sets from its series of updates."""

    def __init__(self) -> None:
        self.beliefs: BeliefSet | None = None
        self.seq = 0

    def apply(self, update: BeliefsUpdate) -> BeliefSet | None:
        """Return the belief set after `update`, or None if it changes an update this
        receiver does not have (it then waits for a whole set)."""
        if not update.base:
            self.beliefs, self.seq = from_wire(update), update.seq
            return self.beliefs
        if self.beliefs is None or update.base != self.seq:
            return None
        old = self.beliefs
        dropped_instances = set(update.dropped_instances)
        inst = {n: t for n, t in old.instances.items() if n not in dropped_instances}
        inst.update(update.instances)
        dropped = {tuple(a) for a in update.dropped_facts}
        facts = (old.facts - dropped) | {tuple(a) for a in update.facts}
        gone = {tuple(a) for a in update.dropped_fluents}
        flu = {a: v for a, v in old.fluents.items() if a not in gone}
        flu.update((tuple(a), float(v)) for a, v in update.fluents)
        self.beliefs = BeliefSet(MappingProxyType(inst), frozenset(facts), MappingProxyType(flu))
        self.seq = update.seq
        return self.beliefs
