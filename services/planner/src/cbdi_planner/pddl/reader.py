"""Shared helpers of the PDDL parser: located errors, typed lists, terms, expressions.

`Reader` knows the file being read and the declarations seen so far, so every check
can name the exact line and column of the offending symbol.
"""

from __future__ import annotations

import math

from cbdi_planner.errors import PddlSyntaxError, SemanticError, UnsupportedFeature
from cbdi_planner.pddl.ast import BinOp, DurationVar, Expr, FHead, Num, Param
from cbdi_planner.pddl.sexpr import SList, SNode, Sym

__all__ = ["Reader"]

_ARITH = {"+", "-", "*", "/"}


class Reader:
    """Turn s-expressions into syntax nodes, raising errors located in `file`."""

    def __init__(self, file: str) -> None:
        self.file = file
        self.predicates: dict[str, tuple[Param, ...]] = {}
        self.functions: dict[str, tuple[Param, ...]] = {}
        self.constants: dict[str, tuple[str, ...]] = {}
        self.types: dict[str, tuple[str, ...]] = {"object": ()}

    # -- errors ---------------------------------------------------------------
    def syntax(self, node: SNode, message: str, expected: str | None = None) -> PddlSyntaxError:
        """Build a syntax error located at `node`."""
        return PddlSyntaxError(
            message, file=self.file, line=node.line, column=node.column, expected=expected
        )

    def semantic(self, node: SNode, message: str, expected: str | None = None) -> SemanticError:
        """Build a semantic error located at `node`."""
        return SemanticError(
            message, file=self.file, line=node.line, column=node.column, expected=expected
        )

    def unsupported(self, node: SNode, message: str) -> UnsupportedFeature:
        """Build an unsupported-feature error located at `node`."""
        return UnsupportedFeature(message, file=self.file, line=node.line, column=node.column)

    # -- shapes ---------------------------------------------------------------
    def as_list(self, node: SNode, expected: str) -> SList:
        """Return `node` as a list or fail saying what list was expected."""
        if not isinstance(node, SList):
            raise self.syntax(node, f"found {node.text!r}", expected)
        return node

    def as_sym(self, node: SNode, expected: str) -> str:
        """Return `node` as a symbol's text or fail saying what was expected."""
        if not isinstance(node, Sym):
            raise self.syntax(node, "found a list", expected)
        return node.text

    def head(self, node: SList) -> str:
        """Return the first symbol of a list ('' for an empty list)."""
        if not node.items:
            return ""
        first = node.items[0]
        return first.text if isinstance(first, Sym) else ""

    def arity(self, node: SList, count: int, expected: str) -> None:
        """Fail unless the list has exactly `count` items."""
        if len(node.items) != count:
            at = node.items[min(len(node.items), count) - 1] if node.items else node
            if len(node.items) > count:
                at = node.items[count]
            raise self.syntax(
                at, f"{self.head(node) or 'list'} needs {count - 1} argument(s)", expected
            )

    def number(self, node: SNode, expected: str = "a number") -> float:
        """Return `node` as a finite number; NaN, infinities and overflows are refused."""
        text = self.as_sym(node, expected)
        try:
            value = float(text)
        except ValueError:
            raise self.syntax(node, f"found {text!r}", expected) from None
        if not math.isfinite(value):
            raise self.syntax(node, f"{text!r} is not a finite number", expected)
        return value

    # -- typed lists ----------------------------------------------------------
    def typed_list(
        self, items: tuple[SNode, ...], variables: bool
    ) -> list[tuple[Sym, tuple[str, ...]]]:
        """Read `a b - t c - (either u v) d` into (name, types); untyped means object."""
        result: list[tuple[Sym, tuple[str, ...]]] = []
        pending: list[Sym] = []
        i = 0
        while i < len(items):
            node = items[i]
            if isinstance(node, Sym) and node.text == "-":
                if i + 1 >= len(items):
                    raise self.syntax(node, "'-' without a type", "a type name")
                types = self.type_spec(items[i + 1])
                result.extend((name, types) for name in pending)
                pending = []
                i += 2
                continue
            if not isinstance(node, Sym):
                raise self.syntax(node, "found a list", "a name" if not variables else "a variable")
            if variables != node.text.startswith("?"):
                what = "a variable (?x)" if variables else "a name"
                raise self.syntax(node, f"found {node.text!r}", what)
            pending.append(node)
            i += 1
        result.extend((name, ("object",)) for name in pending)
        return result

    def type_spec(self, node: SNode) -> tuple[str, ...]:
        """Read a type name or `(either t1 t2 ...)`."""
        if isinstance(node, Sym):
            return (node.text,)
        if self.head(node) != "either" or len(node.items) < 2:
            raise self.syntax(node, "bad type", "a type name or (either ...)")
        return tuple(self.as_sym(item, "a type name") for item in node.items[1:])

    def check_types(self, node: SNode, types: tuple[str, ...]) -> None:
        """Fail if a type is not declared."""
        for name in types:
            if name not in self.types:
                raise self.semantic(node, f"unknown type {name!r}", "a type declared in :types")

    def params(self, node: SNode) -> tuple[Param, ...]:
        """Read a parameter list `(?a - t ?b ?c - u)`."""
        lst = self.as_list(node, "a parameter list '(?x - type ...)'")
        result = []
        for sym, types in self.typed_list(lst.items, variables=True):
            self.check_types(sym, types)
            result.append(Param(sym.text, types))
        return tuple(result)

    # -- terms and expressions ------------------------------------------------
    def term(self, node: SNode, scope: dict[str, Param], constants: bool = True) -> str:
        """Read a term: a variable in scope or a declared constant/object."""
        text = self.as_sym(node, "a variable or an object name")
        if text.startswith("?"):
            if text not in scope:
                raise self.semantic(
                    node, f"variable {text} is not a parameter in scope", "a declared parameter"
                )
        elif constants and text not in self.constants:
            raise self.semantic(node, f"unknown object {text!r}", "a constant or object")
        return text

    def call(
        self, node: SList, decls: dict[str, tuple[Param, ...]], scope: dict[str, Param], what: str
    ) -> tuple[str, tuple[str, ...]]:
        """Read `(name term...)`, checking the name is declared and the arity matches."""
        name_node = node.items[0] if node.items else node
        name = self.as_sym(name_node, f"a {what} name")
        if name not in decls:
            raise self.semantic(name_node, f"unknown {what} {name!r}", f"a declared {what}")
        args = tuple(self.term(arg, scope) for arg in node.items[1:])
        if len(args) != len(decls[name]):
            raise self.semantic(
                node, f"{what} {name!r} takes {len(decls[name])} argument(s), got {len(args)}"
            )
        return name, args

    def expr(self, node: SNode, scope: dict[str, Param]) -> Expr:
        """Read a numeric expression."""
        if isinstance(node, Sym):
            if node.text == "?duration":
                return DurationVar()
            if node.text == "#t":
                raise self.unsupported(node, "continuous effects (#t) are not supported")
            if node.text in self.functions and not self.functions[node.text]:
                return FHead(node.text, ())
            return Num(self.number(node, "a number or an expression"))
        op = self.head(node)
        if op in _ARITH and len(node.items) >= 2:
            operands = [self.expr(item, scope) for item in node.items[1:]]
            if len(operands) == 1:
                return BinOp("-", Num(0.0), operands[0]) if op == "-" else operands[0]
            result = operands[0]
            for operand in operands[1:]:
                result = BinOp(op, result, operand)
            return result
        name, args = self.call(node, self.functions, scope, "function")
        return FHead(name, args)
