"""Reactive rules: when beliefs change, rules whose condition matches change beliefs and desires.

Each rule fires once for every binding of its condition's placeholders; its effects add
or delete beliefs, add or delete desires, or BOOST a desire (extend its goal with the
given literals; the desire is added if the agent does not hold it yet). This is how the
paper's agent reacts to sensing a new object: its goal atom joins the current goal.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from cbdi.beliefs import Belief, BeliefSet
from cbdi_scheduler.conditions import Binding, Condition, bindings, substitute_belief
from cbdi_scheduler.desires import Desire, boosted

__all__ = ["OPERATIONS", "ReactiveRule", "RuleEffect", "RulesOutcome", "fire_rules"]

OPERATIONS = ("ADD", "DEL", "BOOST")


@dataclass(frozen=True)
class RuleEffect:
    """One effect: `target` belief or desire, `op` ADD, DEL or BOOST (desires only)."""

    target: str
    op: str
    belief: Belief | None = None
    desire: Desire | None = None

    def __post_init__(self) -> None:
        if self.op not in OPERATIONS:
            raise ValueError(f"unknown operation {self.op!r} (known: {', '.join(OPERATIONS)})")
        if self.target == "belief" and (self.belief is None or self.op == "BOOST"):
            raise ValueError("a belief effect needs a belief and ADD or DEL")
        if self.target == "desire" and self.desire is None:
            raise ValueError("a desire effect needs a desire")
        if self.target not in ("belief", "desire"):
            raise ValueError(f"effect target must be belief or desire, got {self.target!r}")


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
