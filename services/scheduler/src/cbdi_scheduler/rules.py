"""Reactive rules: when beliefs change, rules whose condition matches change beliefs and desires.

Each rule fires once for every binding of its condition's placeholders; its effects add
or delete beliefs, add or delete desires, or BOOST a desire (extend its goal with the
given literals; the desire is added if the agent does not hold it yet). This is how the
paper's agent reacts to sensing a new object: its goal atom joins the current goal.
An ASK effect asks another agent of the group to add or delete a belief of its own
(`Ask`; the mind sends each once, when its rule starts to match).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from cbdi.beliefs import Belief, BeliefSet
from cbdi_scheduler.conditions import Binding, Condition, bindings, substitute, substitute_belief
from cbdi_scheduler.desires import Desire, boosted

__all__ = ["OPERATIONS", "Ask", "ReactiveRule", "RuleEffect", "RulesOutcome", "fire_rules"]

OPERATIONS = ("ADD", "DEL", "BOOST")
TARGETS = ("belief", "desire", "ask")


@dataclass(frozen=True)
class Ask:
    """A request a rule makes of another agent: add (`ADD`) or delete (`DEL`) `belief` in
    `agent`'s beliefs; its own rules decide what follows."""

    agent: str
    op: str
    belief: Belief


@dataclass(frozen=True)
class RuleEffect:
    """One effect: `target` belief, desire or ask, `op` ADD, DEL or BOOST (desires only).

    An ask names the agent asked in `agent` (a name or a placeholder) and the belief it
    is asked to add or delete.
    """

    target: str
    op: str
    belief: Belief | None = None
    desire: Desire | None = None
    agent: str = ""

    def __post_init__(self) -> None:
        if self.op not in OPERATIONS:
            raise ValueError(f"unknown operation {self.op!r} (known: {', '.join(OPERATIONS)})")
        if self.target not in TARGETS:
            raise ValueError(f"effect target must be one of {', '.join(TARGETS)}: {self.target!r}")
        if self.target != "desire" and (self.belief is None or self.op == "BOOST"):
            raise ValueError(f"a {self.target} effect needs a belief and ADD or DEL")
        if self.target == "desire" and self.desire is None:
            raise ValueError("a desire effect needs a desire")
        if self.target == "ask" and not self.agent:
            raise ValueError("an ask effect needs the agent asked")


@dataclass(frozen=True)
class ReactiveRule:
    """When `condition` holds (per binding), apply `effects`."""

    condition: Condition
    effects: tuple[RuleEffect, ...]
    name: str = ""


@dataclass
class RulesOutcome:
    """What firing the rules did."""

    beliefs: BeliefSet
    desires: dict[str, Desire]
    fired: list[str] = field(default_factory=list)
    boosted: list[str] = field(default_factory=list)
    asks: list[Ask] = field(default_factory=list)  # in rule order, each once


def fire_rules(
    rules: Sequence[ReactiveRule], beliefs: BeliefSet, desires: Mapping[str, Desire], now: float
) -> RulesOutcome:
    """Fire every rule against `beliefs` (all matches first, then all effects, in order)."""
    out = RulesOutcome(beliefs, dict(desires))
    matched = [
        (i, rule, b) for i, rule in enumerate(rules) for b in bindings(rule.condition, beliefs)
    ]
    for i, rule, binding in matched:
        out.fired.append(f"{rule.name or f'rule{i}'}{_show(binding)}")
        for effect in rule.effects:
            _apply(effect, binding, out, now)
    return out


def _show(binding: Binding) -> str:
    return "(" + ", ".join(f"{k}={v}" for k, v in sorted(binding.items())) + ")" if binding else ""


def _apply(effect: RuleEffect, binding: Binding, out: RulesOutcome, now: float) -> None:
    if effect.target == "ask":
        assert effect.belief is not None
        belief = substitute_belief(effect.belief, binding)
        ask = Ask(substitute(effect.agent, binding), effect.op, belief)
        if ask not in out.asks:
            out.asks.append(ask)
        return
    if effect.target == "belief":
        assert effect.belief is not None
        b = substitute_belief(effect.belief, binding)
        out.beliefs = (out.beliefs.adding if effect.op == "ADD" else out.beliefs.removing)([b])
        return
    assert effect.desire is not None
    d = effect.desire.bound(binding)
    held = out.desires.get(d.name)
    if effect.op == "DEL":
        out.desires.pop(d.name, None)
    elif effect.op == "ADD" and held is None:
        out.desires[d.name] = d.due(now)
    elif effect.op == "BOOST":
        if held is None:
            out.desires[d.name] = d.due(now)
        else:
            grown = boosted(held, d.goal, now + d.deadline)
            if grown != held:
                out.desires[d.name] = grown
                out.boosted.append(d.name)
