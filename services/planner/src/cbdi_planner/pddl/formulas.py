"""Read conditions and effects into flat tuples of time-stamped leaves.

A durative action's conditions must be wrapped in `at start`, `over all` or `at end`
and its effects in `at start` or `at end`; an instantaneous action, a goal or a
conditional effect of an instantaneous action uses the time `inst`.
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
    FHead,
    ForallCond,
    ForallEffect,
    Lit,
    NumEffect,
    Param,
    TimedLiteral,
    WhenEffect,
)
from cbdi_planner.pddl.reader import Reader
from cbdi_planner.pddl.sexpr import SList, SNode, Sym

__all__ = ["read_condition", "read_effect"]

_COMPARE = {"<", "<=", "=", ">=", ">"}
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
    r: Reader, node: SNode, scope: dict[str, Param], time: str | None
) -> tuple[Cond, ...]:
    """Read a condition; `time` None means a durative action's untimed top level."""
    lst = r.as_list(node, "a condition '(...)'")
    op = r.head(lst)
    if op == "and":
        return tuple(c for item in lst.items[1:] for c in read_condition(r, item, scope, time))
    if not lst.items:
        return ()
    when = _timed(lst, _COND_TIMES)
    if when is not None:
        if time is not None:
            raise r.syntax(lst, "nested time specifier", "a plain condition")
        return read_condition(r, lst.items[2], scope, when)
    if time is None:
        raise r.syntax(
            lst,
            f"untimed condition {op!r} in a durative action",
            "(at start ...), (over all ...) or (at end ...)",
        )
    if op == "forall":
        r.arity(lst, 3, "(forall (?x - type) condition)")
        params = r.params(lst.items[1])
        body = read_condition(r, lst.items[2], _scope_with(scope, params), time)
        return (ForallCond(params, body),)
    if op in ("or", "imply", "exists"):
        raise r.unsupported(
            lst,
            f"'{op}' in conditions is not supported (only conjunctions, "
            "negation, equality, comparisons and forall)",
        )
    if op == "not":
        r.arity(lst, 2, "(not (predicate ...))")
        inner = r.as_list(lst.items[1], "(not (predicate ...))")
        if r.head(inner) in ("and", "or", "not", "forall", "exists", "imply") or (
            r.head(inner) in _COMPARE and not _is_equality(inner)
        ):
            raise r.unsupported(inner, "negation of a compound or numeric condition")
        return (_literal(r, inner, scope, False, time),)
    if op in _COMPARE and not _is_equality(lst):
        r.arity(lst, 3, f"({op} expression expression)")
        return (Compare(op, r.expr(lst.items[1], scope), r.expr(lst.items[2], scope), time),)
    return (_literal(r, lst, scope, True, time),)


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
        condition = read_condition(r, lst.items[1], scope, time)
        return (WhenEffect(condition, read_effect(r, lst.items[2], scope, time)),)
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
