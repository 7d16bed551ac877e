"""Parse PDDL 2.1 domain and problem files into `Domain` and `Problem`."""

from __future__ import annotations

from cbdi_planner.pddl.ast import (
    INST,
    Action,
    Atom,
    Domain,
    Expr,
    FHead,
    Param,
    Problem,
    TimedLiteral,
)
from cbdi_planner.pddl.formulas import default_time, read_condition, read_effect
from cbdi_planner.pddl.reader import Reader
from cbdi_planner.pddl.sexpr import SList, SNode, Sym, read_sexpr

__all__ = ["parse_domain", "parse_problem"]

_DURATION_OPS = {"=", "<=", ">="}

# Requirements the planner handles (`or`, `imply` and `exists` become disjunctive
# normal form when grounding; see dnf.py).
_SUPPORTED_REQUIREMENTS = {
    ":strips",
    ":typing",
    ":negative-preconditions",
    ":disjunctive-preconditions",
    ":equality",
    ":existential-preconditions",
    ":universal-preconditions",
    ":quantified-preconditions",
    ":conditional-effects",
    ":adl",
    ":fluents",
    ":numeric-fluents",
    ":action-costs",
    ":durative-actions",
    ":duration-inequalities",
    ":timed-initial-literals",
}
_UNSUPPORTED_REQUIREMENTS = {
    ":derived-predicates",
    ":continuous-effects",
    ":object-fluents",
    ":timed-initial-fluents",
    ":preferences",
    ":constraints",
    ":time",
}


def _define(r: Reader, text: str, kind: str) -> tuple[str, SList]:
    """Read `(define (KIND name) ...)` and return the name and the whole list."""
    root = read_sexpr(text, r.file)
    if r.head(root) != "define" or len(root.items) < 2:
        raise r.syntax(
            root.items[0] if root.items else root, "not a PDDL definition", "'(define ...)'"
        )
    header = r.as_list(root.items[1], f"'({kind} NAME)'")
    if r.head(header) != kind or len(header.items) != 2:
        raise r.syntax(header, f"expected a {kind} header", f"'({kind} NAME)'")
    return r.as_sym(header.items[1], f"a {kind} name"), root


def _sections(r: Reader, root: SList) -> list[tuple[str, SList]]:
    result = []
    for node in root.items[2:]:
        lst = r.as_list(node, "a section such as '(:requirements ...)'")
        key = r.head(lst)
        if not key.startswith(":"):
            raise r.syntax(lst, f"found {key or 'a list'!r}", "a section keyword like ':types'")
        result.append((key, lst))
    return result


def parse_domain(text: str, file: str = "<domain>") -> Domain:
    """Parse a domain; raise a located `PddlError` on bad or unsupported input."""
    r = Reader(file)
    name, root = _define(r, text, "domain")
    domain = Domain(name=name, file=file)
    for key, lst in _sections(r, root):
        _domain_section(r, domain, key, lst)
    domain.types = dict(r.types)
    domain.constants = dict(r.constants)
    domain.predicates = dict(r.predicates)
    domain.functions = dict(r.functions)
    return domain


def _domain_section(r: Reader, domain: Domain, key: str, lst: SList) -> None:
    items = lst.items[1:]
    if key == ":requirements":
        domain.requirements = tuple(_requirement(r, item) for item in items)
    elif key == ":types":
        for sym, parents in r.typed_list(items, variables=False):
            r.types[sym.text] = tuple(p for p in parents if p != sym.text)
            for parent in parents:
                r.types.setdefault(parent, ("object",) if parent != "object" else ())
    elif key == ":constants":
        for sym, types in r.typed_list(items, variables=False):
            r.check_types(sym, types)
            r.constants[sym.text] = types
    elif key == ":predicates":
        for node in items:
            decl = r.as_list(node, "a predicate declaration '(name ?x - type)'")
            pname = r.as_sym(decl.items[0] if decl.items else decl, "a predicate name")
            r.predicates[pname] = r.params(
                SList(decl.items[1:], decl.line, decl.column, decl.end_line, decl.end_column)
            )
    elif key == ":functions":
        _functions(r, items)
    elif key in (":action", ":durative-action"):
        domain.actions.append(_action(r, lst, durative=key == ":durative-action"))
    elif key == ":derived":
        raise r.unsupported(lst, "derived predicates are not supported")
    else:
        raise r.syntax(
            lst,
            f"unknown domain section {key!r}",
            ":requirements, :types, :constants, :predicates, :functions, "
            ":action or :durative-action",
        )


def _requirement(r: Reader, node: SNode) -> str:
    """Read one requirement; reject an unknown one and one the planner cannot handle."""
    name = r.as_sym(node, "a requirement like :typing")
    if name in _UNSUPPORTED_REQUIREMENTS:
        raise r.unsupported(node, f"requirement {name} is not supported")
    if name not in _SUPPORTED_REQUIREMENTS:
        raise r.syntax(node, f"unknown requirement {name!r}", "a requirement like :typing")
    return name


def _functions(r: Reader, items: tuple[SNode, ...]) -> None:
    i = 0
    while i < len(items):
        node = items[i]
        if isinstance(node, Sym) and node.text == "-":
            i += 2  # a return type such as `- number`
            continue
        decl = r.as_list(node, "a function declaration '(name ?x - type)'")
        fname = r.as_sym(decl.items[0] if decl.items else decl, "a function name")
        r.functions[fname] = r.params(
            SList(decl.items[1:], decl.line, decl.column, decl.end_line, decl.end_column)
        )
        i += 1


def _action(r: Reader, lst: SList, durative: bool) -> Action:
    name_node = lst.items[1] if len(lst.items) > 1 else lst
    name = r.as_sym(name_node, "an action name")
    fields: dict[str, SNode] = {}
    items = lst.items[2:]
    for i in range(0, len(items), 2):
        key = r.as_sym(items[i], "an action field like :parameters")
        if i + 1 >= len(items):
            raise r.syntax(items[i], f"{key} has no value", "a value after the keyword")
        fields[key] = items[i + 1]
    allowed = (
        {":parameters", ":duration", ":condition", ":effect"}
        if durative
        else {":parameters", ":precondition", ":effect"}
    )
    for key, node in fields.items():
        if key not in allowed:
            raise r.syntax(node, f"unexpected field {key}", " or ".join(sorted(allowed)))
    params = r.params(fields[":parameters"]) if ":parameters" in fields else ()
    scope = {p.name: p for p in params}
    cond_node = fields.get(":condition" if durative else ":precondition")
    time = default_time(durative)
    conditions = read_condition(r, cond_node, scope, time) if cond_node is not None else ()
    effects = read_effect(r, fields[":effect"], scope, time) if ":effect" in fields else ()
    duration = None
    if durative:
        if ":duration" not in fields:
            raise r.syntax(
                lst, f"durative action {name} has no :duration", ":duration (= ?duration N)"
            )
        duration = _duration(r, fields[":duration"], scope)
    return Action(name, params, duration, conditions, effects, lst.line, lst.column)


def _duration(r: Reader, node: SNode, scope: dict[str, Param]) -> tuple[tuple[str, Expr], ...]:
    lst = r.as_list(node, "(= ?duration expression)")
    if r.head(lst) == "and":
        return tuple(c for item in lst.items[1:] for c in _duration(r, item, scope))
    op = r.head(lst)
    if op not in _DURATION_OPS or len(lst.items) != 3:
        if op == "at":
            raise r.unsupported(lst, "timed duration constraints are not supported")
        raise r.syntax(lst, "bad duration constraint", "(= ?duration expr), <= or >=")
    var = lst.items[1]
    if not (isinstance(var, Sym) and var.text == "?duration"):
        raise r.syntax(var, "duration constraint must constrain ?duration", "?duration")
    return ((op, r.expr(lst.items[2], scope)),)


def parse_problem(text: str, domain: Domain, file: str = "<problem>") -> Problem:
    """Parse a problem against `domain`; raise a located `PddlError` on bad input."""
    r = Reader(file)
    r.types = dict(domain.types)
    r.predicates = dict(domain.predicates)
    r.functions = dict(domain.functions)
    r.constants = dict(domain.constants)
    name, root = _define(r, text, "problem")
    problem = Problem(name=name, domain_name="", file=file)
    sections = _sections(r, root)
    for key, lst in sections:  # objects first: init and goal refer to them
        if key == ":objects":
            for sym, types in r.typed_list(lst.items[1:], variables=False):
                r.check_types(sym, types)
                problem.objects[sym.text] = types
                r.constants[sym.text] = types
    for key, lst in sections:
        _problem_section(r, problem, domain, key, lst)
    return problem


def _problem_section(r: Reader, problem: Problem, domain: Domain, key: str, lst: SList) -> None:
    if key == ":domain":
        r.arity(lst, 2, "(:domain NAME)")
        problem.domain_name = r.as_sym(lst.items[1], "a domain name")
        if problem.domain_name != domain.name:
            raise r.semantic(
                lst.items[1],
                f"problem is for domain {problem.domain_name!r}, not {domain.name!r}",
                f"(:domain {domain.name})",
            )
    elif key == ":init":
        for node in lst.items[1:]:
            _init_item(r, problem, r.as_list(node, "an initial fact '(p ...)'"))
    elif key == ":goal":
        r.arity(lst, 2, "(:goal condition)")
        problem.goal = read_condition(r, lst.items[1], {}, INST)
    elif key == ":metric":
        problem.metric = " ".join(_flatten(lst.items[1:]))
    elif key not in (":objects", ":requirements"):
        raise r.syntax(
            lst, f"unknown problem section {key!r}", ":domain, :objects, :init, :goal or :metric"
        )


def _flatten(nodes: tuple[SNode, ...]) -> list[str]:
    out: list[str] = []
    for node in nodes:
        out.extend([node.text] if isinstance(node, Sym) else ["(", *_flatten(node.items), ")"])
    return out


def _init_item(r: Reader, problem: Problem, lst: SList) -> None:
    op = r.head(lst)
    items = lst.items
    if op == "at" and len(items) == 3 and isinstance(items[2], SList) and isinstance(items[1], Sym):
        when = r.number(items[1], "a time (a number)")
        inner = items[2]
        positive = r.head(inner) != "not"
        if not positive:
            r.arity(inner, 2, "(not (p ...))")
            inner = r.as_list(inner.items[1], "(p ...)")
        name, args = r.call(inner, r.predicates, {}, "predicate")
        problem.timed_literals.append((when, TimedLiteral(Atom(name, args), positive, INST)))
    elif op == "=" and len(items) == 3 and isinstance(items[1], SList):
        name, args = r.call(items[1], r.functions, {}, "function")
        problem.init_numeric[FHead(name, args)] = r.number(items[2], "a numeric value")
    elif op == "not":
        return  # closed world: an explicit negative initial fact changes nothing
    else:
        name, args = r.call(lst, r.predicates, {}, "predicate")
        problem.init.append(Atom(name, args))
