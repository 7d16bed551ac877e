"""Find the action instances reachable from the initial state (lifted, relaxed).

Grounding every parameter combination explodes; instead, atoms are discovered from the
initial state outwards (deletes ignored) and an action instance is created only when
its binding conditions (static facts, and start conditions) can all be true. This is
the usual semi-naive fixpoint: each new atom triggers only the joins it takes part in.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from dataclasses import dataclass

from cbdi_planner.pddl.ast import (
    ALL,
    END,
    Action,
    Domain,
    Effect,
    ForallEffect,
    Lit,
    Param,
    Problem,
    TimedLiteral,
    WhenEffect,
)

__all__ = ["GAtom", "Instance", "Objects", "reachable_instances"]

GAtom = tuple[str, ...]  # (predicate, arg1, arg2, ...)
Binding = dict[str, str]


class Objects:
    """Objects by type, honouring the type hierarchy and `either`."""

    def __init__(self, domain: Domain, problem: Problem) -> None:
        self.types_of: dict[str, set[str]] = {}
        declared = {**domain.constants, **problem.objects}
        for name, types in declared.items():
            closure: set[str] = {"object"}
            for t in types:
                closure |= self._ancestors(domain.types, t)
            self.types_of[name] = closure
        self.of_type: dict[str, list[str]] = {}
        for name in declared:
            for t in self.types_of[name]:
                self.of_type.setdefault(t, []).append(name)

    @staticmethod
    def _ancestors(types: dict[str, tuple[str, ...]], t: str) -> set[str]:
        seen, stack = set(), [t]
        while stack:
            current = stack.pop()
            if current not in seen:
                seen.add(current)
                stack.extend(types.get(current, ()))
        return seen

    def candidates(self, param: Param) -> list[str]:
        """Return the objects a parameter can take."""
        if len(param.types) == 1:
            return self.of_type.get(param.types[0], [])
        merged: dict[str, None] = {}
        for t in param.types:
            merged.update(dict.fromkeys(self.of_type.get(t, [])))
        return list(merged)

    def fits(self, obj: str, param: Param) -> bool:
        """Tell whether `obj` has one of the parameter's types."""
        return any(t in self.types_of.get(obj, ()) for t in param.types)


@dataclass(frozen=True, slots=True)
class Instance:
    """An action schema with every parameter bound to an object."""

    action: Action
    args: tuple[str, ...]

    def binding(self) -> Binding:
        """Return the parameter-to-object map."""
        return {p.name: a for p, a in zip(self.action.params, self.args, strict=True)}


def fluent_predicates(domain: Domain, problem: Problem) -> set[str]:
    """Return the predicates some effect or timed literal changes; the rest are static."""
    names = {lit.atom.predicate for _, lit in problem.timed_literals}
    for action in domain.actions:
        for effect in _walk_effects(action.effects):
            if isinstance(effect, TimedLiteral):
                names.add(effect.atom.predicate)
    return names


def _walk_effects(effects: tuple[Effect, ...]) -> Iterator[Effect]:
    for effect in effects:
        if isinstance(effect, ForallEffect | WhenEffect):
            yield from _walk_effects(effect.body)
        else:
            yield effect


def _binding_conds(action: Action, fluent: set[str]) -> list[Lit]:
    """Pick the conditions used to join: static ones, and fluents needed at the start.

    Invariants and end conditions on fluents are left out: the action's own start
    effects may make them true, so requiring them now would lose real instances.
    """
    out = []
    for cond in action.conditions:
        if isinstance(cond, Lit) and cond.positive and cond.atom.predicate != "=":
            static = cond.atom.predicate not in fluent
            if static or cond.time not in (ALL, END):
                out.append(cond)
    return out


class _Index:
    def __init__(self) -> None:
        self.by_pred: dict[str, list[tuple[str, ...]]] = {}
        self.by_pos: dict[tuple[str, int, str], list[tuple[str, ...]]] = {}
        self.atoms: set[GAtom] = set()

    def add(self, atom: GAtom) -> bool:
        if atom in self.atoms:
            return False
        self.atoms.add(atom)
        args = atom[1:]
        self.by_pred.setdefault(atom[0], []).append(args)
        for pos, value in enumerate(args):
            self.by_pos.setdefault((atom[0], pos, value), []).append(args)
        return True


def _unify(terms: tuple[str, ...], args: tuple[str, ...], binding: Binding) -> Binding | None:
    new = binding
    for term, value in zip(terms, args, strict=True):
        if term.startswith("?"):
            bound = new.get(term)
            if bound is None:
                if new is binding:
                    new = dict(binding)
                new[term] = value
            elif bound != value:
                return None
        elif term != value:
            return None
    return new


def _join(conds: list[Lit], binding: Binding, index: _Index) -> Iterator[Binding]:
    if not conds:
        yield binding
        return
    best, best_key = 0, None
    for i, cond in enumerate(conds):
        for pos, term in enumerate(cond.atom.args):
            value = binding.get(term, None) if term.startswith("?") else term
            if value is not None:
                best, best_key = i, (cond.atom.predicate, pos, value)
                break
        if best_key is not None:
            break
    cond = conds[best]
    rest = conds[:best] + conds[best + 1 :]
    pool = (
        index.by_pos.get(best_key, []) if best_key else index.by_pred.get(cond.atom.predicate, [])
    )
    for args in list(pool):
        unified = _unify(cond.atom.args, args, binding)
        if unified is not None:
            yield from _join(rest, unified, index)


def _complete(action: Action, binding: Binding, objects: Objects) -> Iterator[tuple[str, ...]]:
    """Enumerate the unbound parameters by type and check the types of the bound ones."""
    free = [p for p in action.params if p.name not in binding]
    for p in action.params:
        if p.name in binding and not objects.fits(binding[p.name], p):
            return
    for values in itertools.product(*(objects.candidates(p) for p in free)):
        full = dict(binding)
        full.update(zip((p.name for p in free), values, strict=True))
        yield tuple(full[p.name] for p in action.params)


def _equalities_hold(action: Action, args: tuple[str, ...]) -> bool:
    env = {p.name: a for p, a in zip(action.params, args, strict=True)}
    for cond in action.conditions:
        if isinstance(cond, Lit) and cond.atom.predicate == "=":
            left, right = (env.get(t, t) for t in cond.atom.args)
            if (left == right) != cond.positive:
                return False
    return True


def _adds(effects: tuple[Effect, ...], env: Binding, objects: Objects) -> Iterator[GAtom]:
    for effect in effects:
        if isinstance(effect, TimedLiteral):
            if effect.positive:
                yield (effect.atom.predicate, *(env.get(t, t) for t in effect.atom.args))
        elif isinstance(effect, WhenEffect):
            yield from _adds(effect.body, env, objects)
        elif isinstance(effect, ForallEffect):
            for values in itertools.product(*(objects.candidates(p) for p in effect.params)):
                inner = dict(env)
                inner.update(zip((p.name for p in effect.params), values, strict=True))
                yield from _adds(effect.body, inner, objects)


def reachable_instances(
    domain: Domain, problem: Problem, objects: Objects, fluent: set[str]
) -> tuple[list[Instance], set[GAtom]]:
    """Return the relaxed-reachable action instances and atoms (deletes ignored)."""
    index = _Index()
    queue: list[GAtom] = []
    initial = [(a.predicate, *a.args) for a in problem.init]
    initial += [
        (lit.atom.predicate, *lit.atom.args) for _, lit in problem.timed_literals if lit.positive
    ]
    for atom in initial:
        if index.add(atom):
            queue.append(atom)
    joins = {a.name: _binding_conds(a, fluent) for a in domain.actions}
    triggers: dict[str, list[tuple[Action, int]]] = {}
    for action in domain.actions:
        for k, cond in enumerate(joins[action.name]):
            triggers.setdefault(cond.atom.predicate, []).append((action, k))
    seen: dict[tuple[str, tuple[str, ...]], Instance] = {}

    def found(action: Action, binding: Binding) -> None:
        for args in _complete(action, binding, objects):
            key = (action.name, args)
            if key in seen or not _equalities_hold(action, args):
                continue
            seen[key] = Instance(action, args)
            env = seen[key].binding()
            for atom in _adds(action.effects, env, objects):
                if index.add(atom):
                    queue.append(atom)

    for action in domain.actions:
        if not joins[action.name]:
            found(action, {})
    head = 0
    while head < len(queue):
        atom = queue[head]
        head += 1
        for action, k in triggers.get(atom[0], []):
            conds = joins[action.name]
            start = _unify(conds[k].atom.args, atom[1:], {})
            if start is not None:
                for binding in list(_join(conds[:k] + conds[k + 1 :], start, index)):
                    found(action, binding)
    return list(seen.values()), index.atoms
