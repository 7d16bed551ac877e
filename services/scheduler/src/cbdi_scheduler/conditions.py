"""Conditions in disjunctive normal form over beliefs, with placeholders and wildcards.

A `Condition` is a disjunction of clauses; a clause is a conjunction of literals. Each
literal checks one belief pattern whose strings may be placeholders (`{x}`) or the
wildcard `*`:

- `T`: some predicate fact unifies with the pattern;  `F`: none does (negation as failure);
- `EX`: an instance exists (its name may be a placeholder, its type restricts);
- `EQ`, `NE`, `LT`, `LE`, `GT`, `GE`: a function's value compares with `value`.

`bindings(condition, beliefs)` returns every binding of the placeholders that makes the
condition true, in a stable order, so a reactive rule fires once per binding.
"""

from __future__ import annotations

import operator
import re
from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace

from cbdi.beliefs import FUNCTION, INSTANCE, PREDICATE, Belief, BeliefSet

__all__ = [
    "CHECKS",
    "Binding",
    "Clause",
    "Condition",
    "Literal",
    "bindings",
    "holds",
    "substitute",
    "substitute_belief",
]

Binding = dict[str, str]
WILDCARD = "*"
_PLACEHOLDER = re.compile(r"\{(\w+)\}")
_NUMERIC: dict[str, Callable[[float, float], bool]] = {
    "EQ": operator.eq,
    "NE": operator.ne,
    "LT": operator.lt,
    "LE": operator.le,
    "GT": operator.gt,
    "GE": operator.ge,
}
CHECKS = ("T", "F", "EX", *_NUMERIC)


@dataclass(frozen=True)
class Literal:
    """One check of one belief pattern."""

    check: str
    belief: Belief
    value: float = 0.0

    def __post_init__(self) -> None:
        if self.check not in CHECKS:
            raise ValueError(f"unknown check {self.check!r} (known: {', '.join(CHECKS)})")
        wanted = {"T": PREDICATE, "F": PREDICATE, "EX": INSTANCE}.get(self.check, FUNCTION)
        if self.belief.kind != wanted:
            raise ValueError(
                f"check {self.check} needs a {wanted} belief, "
                f"got a {self.belief.kind} ({self.belief.name})"
            )


Clause = tuple[Literal, ...]
Condition = tuple[Clause, ...]  # () is always true


def substitute(text: str, binding: Binding) -> str:
    """Replace every bound `{x}` in `text` (also inside names such as `patrol_{x}`)."""
    return _PLACEHOLDER.sub(lambda m: binding.get(m.group(1), m.group(0)), text)


def substitute_belief(b: Belief, binding: Binding) -> Belief:
    """Return `b` with its placeholders replaced by their bindings."""
    return replace(
        b, name=substitute(b.name, binding), params=tuple(substitute(p, binding) for p in b.params)
    )


def _unify(pattern: tuple[str, ...], values: tuple[str, ...], binding: Binding) -> Binding | None:
    if len(pattern) != len(values):
        return None
    out = binding
    for p, v in zip(pattern, values, strict=True):
        if p == WILDCARD:
            continue
        m = _PLACEHOLDER.fullmatch(p)
        if m is None:
            if p != v:
                return None
            continue
        bound = out.get(m.group(1))
        if bound is None:
            out = {**out, m.group(1): v}
        elif bound != v:
            return None
    return out


def _literal(lit: Literal, beliefs: BeliefSet, binding: Binding) -> Iterator[Binding]:
    b = substitute_belief(lit.belief, binding)
    if lit.check == "EX":
        for name, type_ in beliefs.sorted_instances:
            if b.type and type_ != b.type:
                continue
            found = _unify((b.name,), (name,), binding)
            if found is not None:
                yield found
    elif lit.check in ("T", "F"):
        if not any(p == WILDCARD or "{" in p for p in b.params):  # ground: look it up
            if (b.atom in beliefs.facts) == (lit.check == "T"):
                yield binding
            return
        matches = (_unify(b.params, atom[1:], binding) for atom in beliefs.facts_of(b.name))
        found_any = [m for m in matches if m is not None]
        if lit.check == "T":
            yield from found_any
        elif not found_any:
            yield binding
    else:
        compare = _NUMERIC[lit.check]
        for atom, value in beliefs.fluents_of(b.name):
            if compare(value, lit.value):
                found = _unify(b.params, atom[1:], binding)
                if found is not None:
                    yield found


def _clause(clause: Clause, beliefs: BeliefSet, binding: Binding) -> list[Binding]:
    current = [binding]
    for lit in clause:
        current = [found for b in current for found in _literal(lit, beliefs, b)]
        if not current:
            break
    return current


def bindings(
    condition: Condition, beliefs: BeliefSet, binding: Binding | None = None
) -> list[Binding]:
    """Return every distinct binding under which `condition` holds (empty list: false)."""
    start = binding or {}
    if not condition:
        return [start]
    seen: list[Binding] = []
    for clause in condition:
        for found in _clause(clause, beliefs, start):
            if found not in seen:
                seen.append(found)
    return seen


def holds(condition: Condition, beliefs: BeliefSet) -> bool:
    """Return whether `condition` holds for some binding."""
    return bool(bindings(condition, beliefs))
