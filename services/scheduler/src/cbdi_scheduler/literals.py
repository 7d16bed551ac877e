"""Read beliefs and condition literals written the PDDL way, as agent files do.

(map_loaded)                     a predicate belief, or a `T` check
(not (carrying {self} *))        an `F` check
(exists {x} - parcel)            an `EX` check;   `p1 - parcel`  an instance belief
(= (battery {self}) 20)          a function belief, or an `EQ` check
(< (battery {self}) 10)          numeric checks: < <= > >= = !=
"""

from __future__ import annotations

import math
import re

from cbdi.beliefs import Belief, fact, fluent, instance
from cbdi_scheduler.conditions import Literal

__all__ = ["LiteralSyntaxError", "parse_belief", "parse_literal"]

_TOKEN = re.compile(r"\(|\)|[^\s()]+")
_OPS = {"=": "EQ", "!=": "NE", "<": "LT", "<=": "LE", ">": "GT", ">=": "GE"}
Tree = str | list["Tree"]


class LiteralSyntaxError(ValueError):
    """A belief or literal that does not read; the message says what was expected."""


def _tree(text: str) -> list[Tree]:
    tokens = _TOKEN.findall(text)
    if not tokens:
        raise LiteralSyntaxError(f"{text!r}: empty")
    stack: list[list[Tree]] = [[]]
    for tok in tokens:
        if tok == "(":
            stack.append([])
        elif tok == ")":
            if len(stack) == 1:
                raise LiteralSyntaxError(f"{text!r}: unbalanced ')'")
            done = stack.pop()
            stack[-1].append(done)
        else:
            stack[-1].append(tok)
    if len(stack) != 1:
        raise LiteralSyntaxError(f"{text!r}: missing ')'")
    return stack[0]  # the top-level items


def _one(top: list[Tree], text: str) -> list[Tree]:
    """Return the single parenthesised expression `text` must be."""
    if len(top) != 1 or not isinstance(top[0], list):
        raise LiteralSyntaxError(f"{text!r}: expected one expression in parentheses")
    return top[0]


def _atom(tree: Tree, text: str) -> tuple[str, tuple[str, ...]]:
    if not isinstance(tree, list) or not tree or not all(isinstance(t, str) for t in tree):
        raise LiteralSyntaxError(f"{text!r}: expected an atom like (name arg ...)")
    return str(tree[0]), tuple(str(t) for t in tree[1:])


def _number(tok: Tree, text: str) -> float:
    try:
        value = float(str(tok))
    except ValueError:
        raise LiteralSyntaxError(f"{text!r}: expected a number, got {tok!r}") from None
    if not math.isfinite(value):
        raise LiteralSyntaxError(f"{text!r}: expected a finite number, got {tok!r}")
    return value


def parse_belief(text: str) -> Belief:
    """Read one belief: `(pred a b)`, `(= (func a) 3)` or `name - type`."""
    top = _tree(text)
    if len(top) == 3 and top[1] == "-" and all(isinstance(t, str) for t in top):
        return instance(str(top[0]), str(top[2]))
    tree = _one(top, text)
    if tree and tree[0] == "=" and len(tree) == 3:
        name, args = _atom(tree[1], text)
        return fluent(name, *args, value=_number(tree[2], text))
    name, args = _atom(tree, text)
    return fact(name, *args)


def parse_literal(text: str) -> Literal:
    """Read one condition literal (see the module docstring for the forms)."""
    tree = _one(_tree(text), text)
    if tree and tree[0] == "not" and len(tree) == 2:
        name, args = _atom(tree[1], text)
        return Literal("F", fact(name, *args))
    if tree and tree[0] == "exists":
        if len(tree) != 4 or tree[2] != "-" or not all(isinstance(t, str) for t in tree[1:]):
            raise LiteralSyntaxError(f"{text!r}: expected (exists NAME - TYPE)")
        return Literal("EX", instance(str(tree[1]), str(tree[3])))
    if tree and isinstance(tree[0], str) and tree[0] in _OPS and len(tree) == 3:
        name, args = _atom(tree[1], text)
        return Literal(_OPS[str(tree[0])], fluent(name, *args, value=0.0), _number(tree[2], text))
    name, args = _atom(tree, text)
    return Literal("T", fact(name, *args))
