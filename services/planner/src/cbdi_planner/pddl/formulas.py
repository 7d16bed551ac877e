"""Read conditions and effects into flat tuples of time-stamped leaves.

A durative action's conditions must be wrapped in `at start`, `over all` or `at end`
and its effects in `at start` or `at end`; an instantaneous action, a goal or a
conditional effect of an instantaneous action uses the time `inst`. Disjunctions stay
lifted (`OrCond`, `ExistsCond`); grounding turns them into disjunctive normal form.
"""

from __future__ import annotations

from cbdi_planner.pddl.ast import (
    ALL,
    END,
    INST,
    START,
    Atom,
    Compare,
    Cond,
    Effect,
    ExistsCond,
    FHead,
    ForallCond,
    ForallEffect,
    Lit,
    NumEffect,
    OrCond,
    Param,
    TimedLiteral,
    WhenEffect,
)
from cbdi_planner.pddl.reader import Reader
from cbdi_planner.pddl.sexpr import SList, SNode, Sym

__all__ = ["read_condition", "read_effect"]

_COMPARE = {"<", "<=", "=", ">=", ">"}
_NEGATED = {"<": ">=", "<=": ">", ">=": "<", ">": "<="}
_NUM_EFFECTS = {"increase", "decrease", "assign", "scale-up", "scale-down"}
_COND_TIMES = {("at", "start"): START, ("over", "all"): ALL, ("at", "end"): END}
_EFF_TIMES = {("at", "start"): START, ("at", "end"): END}


def _timed(node: SList, table: dict[tuple[str, str], str]) -> str | None:
    """Return the time of `(at start X)`-like wrappers, None for anything else."""
    if len(node.items) != 3 or not isinstance(node.items[2], SList):
        return None
    first, second = node.items[0], node.items[1]
    if not (isinstance(first, Sym) and isinstance(second, Sym)):
        return None
    return table.get((first.text, second.text))


def _scope_with(scope: dict[str, Param], params: tuple[Param, ...]) -> dict[str, Param]:
    inner = dict(scope)
    inner.update({p.name: p for p in params})
    return inner


def read_condition(
    r: Reader,
    node: SNode,
    scope: dict[str, Param],
    time: str | None,
    positive: bool = True,
    retime: bool = False,
) -> tuple[Cond, ...]:
    """Read a condition, negated unless `positive`; `time` None means a durative
    action's untimed top level.

    Negation is pushed down to literals and comparisons (De Morgan; `not forall` is
    `exists not`, `not exists` is `forall not`) and `(imply a b)` is read as
    `(or (not a) b)`, so later stages see only `and`, `or`, `forall` and `exists`.
    `retime` lets a time specifier inside override `time` (a `when` condition inside
    a timed effect may name the time it is checked at).
    """
    lst = r.as_list(node, "a condition '(...)'")
    op = r.head(lst)
    if op == "and":
        parts = [read_condition(r, i, scope, time, positive, retime) for i in lst.items[1:]]
        return _all(parts) if positive else _any(lst, parts)
    if not lst.items:
        return () if positive else _any(lst, [])
    when = _timed(lst, _COND_TIMES)
    if when is not None:
        if time is not None and not retime:
            raise r.syntax(lst, "nested time specifier", "a plain condition")
        return read_condition(r, lst.items[2], scope, when, positive)
    if time is None:
        raise r.syntax(
            lst,
            f"untimed condition {op!r} in a durative action",
            "(at start ...), (over all ...) or (at end ...)",
        )
    if op in ("or", "imply", "not"):
        return _connective(r, lst, scope, time, positive, retime)
    if op in ("forall", "exists"):
        r.arity(lst, 3, f"({op} (?x - type) condition)")
        params = r.params(lst.items[1])
        body = read_condition(r, lst.items[2], _scope_with(scope, params), time, positive, retime)
        if (op == "forall") == positive:
            return (ForallCond(params, body),)
        return (ExistsCond(params, body, lst.line, lst.column),)
    if op in _COMPARE and not _is_equality(lst):
        r.arity(lst, 3, f"({op} expression expression)")
        lhs, rhs = r.expr(lst.items[1], scope), r.expr(lst.items[2], scope)
        if positive:
            return (Compare(op, lhs, rhs, time),)
        if op == "=":
            return _any(lst, [(Compare("<", lhs, rhs, time),), (Compare(">", lhs, rhs, time),)])
        return (Compare(_NEGATED[op], lhs, rhs, time),)
    return (_literal(r, lst, scope, positive, time),)


def _connective(
    r: Reader, lst: SList, scope: dict[str, Param], time: str, positive: bool, retime: bool
) -> tuple[Cond, ...]:
    """Read `or`, `imply` and `not`, with the polarity pushed to their arguments."""
    op = r.head(lst)
    if op == "not":
        r.arity(lst, 2, "(not condition)")
        return read_condition(r, lst.items[1], scope, time, not positive, retime)
    if op == "imply":
        r.arity(lst, 3, "(imply condition condition)")
        premise = read_condition(r, lst.items[1], scope, time, not positive, retime)
        conclusion = read_condition(r, lst.items[2], scope, time, positive, retime)
        return _any(lst, [premise, conclusion]) if positive else _all([premise, conclusion])
    parts = [read_condition(r, i, scope, time, positive, retime) for i in lst.items[1:]]
    return _any(lst, parts) if positive else _all(parts)


def _all(parts: list[tuple[Cond, ...]]) -> tuple[Cond, ...]:
    return tuple(c for part in parts for c in part)


def _any(lst: SList, parts: list[tuple[Cond, ...]]) -> tuple[Cond, ...]:
    """Build a disjunction; one part is just that part, and nested ones are flattened."""
    if len(parts) == 1:
        return parts[0]
    flat: list[tuple[Cond, ...]] = []
    for part in parts:
        if len(part) == 1 and isinstance(part[0], OrCond):
            flat.extend(part[0].parts)
        else:
            flat.append(part)
    return (OrCond(tuple(flat), lst.line, lst.column),)


def _is_equality(lst: SList) -> bool:
    """Tell `(= ?a ?b)` on objects from a numeric `(= (f) 3)`."""
    return (
        (r_head := lst.items[0]) is not None
        and isinstance(r_head, Sym)
        and (
            r_head.text == "="
            and len(lst.items) == 3
            and all(isinstance(i, Sym) and not _numeric(i.text) for i in lst.items[1:])
        )
    )


def _numeric(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _literal(r: Reader, lst: SList, scope: dict[str, Param], positive: bool, time: str) -> Lit:
    if _is_equality(lst):
        args = tuple(r.term(item, scope) for item in lst.items[1:])
        return Lit(Atom("=", args), positive, time)
    name, args = r.call(lst, r.predicates, scope, "predicate")
    return Lit(Atom(name, args), positive, time)


def read_effect(
    r: Reader, node: SNode, scope: dict[str, Param], time: str | None
) -> tuple[Effect, ...]:
    """Read an effect; `time` None means a durative action's untimed top level."""
    lst = r.as_list(node, "an effect '(...)'")
    op = r.head(lst)
    if op == "and":
        return tuple(e for item in lst.items[1:] for e in read_effect(r, item, scope, time))
    if not lst.items:
        return ()
    if op == "forall":
        r.arity(lst, 3, "(forall (?x - type) effect)")
        params = r.params(lst.items[1])
        return (
            ForallEffect(params, read_effect(r, lst.items[2], _scope_with(scope, params), time)),
        )
    if op == "when":
        r.arity(lst, 3, "(when condition effect)")
        retime = time in (START, END)
        condition = read_condition(r, lst.items[1], scope, time, retime=retime)
        body = read_effect(r, lst.items[2], scope, time)
        return (WhenEffect(condition, body, lst.line, lst.column),)
    when = _timed(lst, _EFF_TIMES)
    if when is not None:
        if time is not None:
            raise r.syntax(lst, "nested time specifier", "a plain effect")
        return read_effect(r, lst.items[2], scope, when)
    if time is None:
        raise r.syntax(
            lst, f"untimed effect {op!r} in a durative action", "(at start ...) or (at end ...)"
        )
    return (_simple_effect(r, lst, scope, time),)


def _simple_effect(r: Reader, lst: SList, scope: dict[str, Param], time: str) -> Effect:
    op = r.head(lst)
    if op in _NUM_EFFECTS:
        r.arity(lst, 3, f"({op} (function ...) expression)")
        target = r.as_list(lst.items[1], "a function term '(f ...)'")
        name, args = r.call(target, r.functions, scope, "function")
        return NumEffect(op, FHead(name, args), r.expr(lst.items[2], scope), time)
    if op == "not":
        r.arity(lst, 2, "(not (predicate ...))")
        inner = r.as_list(lst.items[1], "(not (predicate ...))")
        name, args = r.call(inner, r.predicates, scope, "predicate")
        return TimedLiteral(Atom(name, args), False, time)
    name, args = r.call(lst, r.predicates, scope, "predicate")
    return TimedLiteral(Atom(name, args), True, time)


def default_time(durative: bool) -> str | None:
    """Return the top-level time of an action body: None (must be timed) or `inst`."""
    return None if durative else INST
