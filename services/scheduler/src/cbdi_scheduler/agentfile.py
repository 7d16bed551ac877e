"""Agent files: one TOML file describes a kind of agent (format in docs/agents.md).

`{self}` anywhere stands for the agent's own name, given when the agent is started, so
one file serves several robots. Every mistake is an `AgentFileError` naming the file,
the field (`rules[0].then[1].boost.goal[0]`) and what is wrong.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

from cbdi.agentfile import (
    AgentFileError,
    PlanningSettings,
    RawAgentFile,
    domain_functions,
    domain_signature,
    parse_agent_text,
    read_agent_file,
)
from cbdi.beliefs import FUNCTION, INSTANCE, PREDICATE, Belief
from cbdi.keys import validate_name
from cbdi_scheduler.conditions import Condition
from cbdi_scheduler.desires import NO_DEADLINE, Desire
from cbdi_scheduler.intentions import StallCounts
from cbdi_scheduler.knowledge import available
from cbdi_scheduler.literals import LiteralSyntaxError, parse_belief, parse_literal
from cbdi_scheduler.rules import ReactiveRule, RuleEffect

__all__ = [
    "AgentFile",
    "AgentFileError",
    "PlanningSettings",
    "load_agent",
    "parse_agent",
    "undeclared",
]

# Re-exported: the common parts of agent files live in the common library.
_SHARED = (AgentFileError, PlanningSettings)

PREEMPTION = ("no_preempt", "preempt", "clean_preempt")


@dataclass(frozen=True)
class AgentFile:
    """A loaded agent file, for one named agent."""

    agent: str
    source: str
    domain: Path
    group: str = ""
    allowed_groups: tuple[str, ...] = ()
    detection_depth: int | None = None
    preemption: str = "clean_preempt"
    plan_retries: int = 3
    exec_retries: int = 3
    rtc_deadline: float = 2.0  # the executing desire's deadline: this many times its span
    wait_stall: float = 8.0  # s a blocked wait may see nothing change before it counts
    # Up to this fraction of wait_stall more, drawn per agent and stall (see intentions).
    wait_stall_spread: float = 0.0
    wait_stall_counts: StallCounts = "quiet"  # what wait_stall counts (see intentions)
    claim: tuple[str, ...] = ()  # goal predicates whose first argument the group shares out
    knowledge: str = "literals"  # the domain knowledge (cbdi.knowledge entry point) to load
    beliefs: tuple[Belief, ...] = ()
    desires: tuple[Desire, ...] = ()
    rules: tuple[ReactiveRule, ...] = ()
    planning: PlanningSettings = field(default_factory=PlanningSettings)
    # The domain's predicates and functions with their arities, and the file's private
    # predicates: what beliefs, goals and conditions may name (requests are checked too).
    signature: Mapping[str, int] = field(default_factory=dict)
    private_predicates: frozenset[str] = frozenset()
    functions: frozenset[str] = frozenset()  # which of the signature's are functions


def load_agent(path: str | Path, agent: str) -> AgentFile:
    """Read the agent file at `path` for the agent named `agent`."""
    return _interpret(read_agent_file(path, agent), agent)


def parse_agent(text: str, source: str, agent: str, base: Path) -> AgentFile:
    """Validate agent-file `text` (with `{self}` already replaced)."""
    return _interpret(parse_agent_text(text, source, base), agent)


def _interpret(raw: RawAgentFile, agent: str) -> AgentFile:
    data, source, domain = raw.data, raw.source, raw.domain
    r = _Reader(source, data)
    text = _domain_text(source, domain)
    r.signature, r.functions = domain_signature(text), domain_functions(text)
    r.private = frozenset(
        r.check(p, str, f"private_predicates[{i}]")
        for i, p in enumerate(r.opt(data, "private_predicates", list, []))
    )
    bdi = r.table(data, "scheduler")
    preemption = r.choice(bdi, "preemption", PREEMPTION, "clean_preempt", "scheduler")
    return AgentFile(
        agent=agent,
        source=source,
        domain=domain,
        group=r.opt(data, "group", str, ""),
        allowed_groups=tuple(r.opt(data, "allowed_groups", list, [])),
        detection_depth=r.natural(data, "detection_depth", None),
        preemption=preemption,
        plan_retries=r.natural(bdi, "plan_retries", 3, "scheduler"),
        exec_retries=r.natural(bdi, "exec_retries", 3, "scheduler"),
        rtc_deadline=_rtc_deadline(r.opt(bdi, "rtc_deadline", float, 2.0, "scheduler"), source),
        wait_stall=_wait_stall(r.opt(bdi, "wait_stall", float, 8.0, "scheduler"), source),
        wait_stall_spread=_spread(r.opt(bdi, "wait_stall_spread", float, 0.0, "scheduler"), source),
        wait_stall_counts=_stall_counts(
            r.opt(bdi, "wait_stall_counts", str, "quiet", "scheduler"), source
        ),
        knowledge=_knowledge(r.opt(data, "knowledge", str, "literals"), source),
        claim=tuple(
            r.check(p, str, f"scheduler.claim[{i}]")
            for i, p in enumerate(r.opt(bdi, "claim", list, [], "scheduler"))
        ),
        beliefs=tuple(
            r.belief(b, f"beliefs[{i}]") for i, b in enumerate(r.opt(data, "beliefs", list, []))
        ),
        desires=tuple(
            r.desire(d, f"desires[{i}]") for i, d in enumerate(r.opt(data, "desires", list, []))
        ),
        rules=tuple(r.rule(x, f"rules[{i}]") for i, x in enumerate(r.opt(data, "rules", list, []))),
        planning=raw.planning,
        signature=r.signature,
        private_predicates=r.private,
        functions=r.functions,
    )


def undeclared(
    belief: Belief,
    signature: Mapping[str, int],
    private: frozenset[str],
    goal: bool = False,
    functions: frozenset[str] | None = None,
) -> str:
    """Say why `belief` names nothing the domain declares with that arity (nor, outside
    goals, a private predicate); "" when it does. Given the domain's `functions`, a
    function value must name a function and an atom a predicate."""
    if belief.kind == INSTANCE:
        return ""
    arity = signature.get(belief.name)
    if arity is None:
        if not goal and belief.name in private:
            return ""
        where_else = "" if goal else " nor in private_predicates"
        return f"{belief.name!r} is not declared by the domain{where_else}"
    if functions is not None:
        is_function = belief.name in functions
        if belief.kind == FUNCTION and not is_function:
            return f"{belief.name!r} is a predicate of the domain, not a function"
        if belief.kind != FUNCTION and is_function:
            value = f"(= ({belief.name} ...) N)"
            return f"{belief.name!r} is a function of the domain: give its value, {value}"
    if len(belief.params) != arity:
        return f"{belief.name!r} takes {arity} argument(s), got {len(belief.params)}"
    return ""


def _knowledge(name: str, source: str) -> str:
    installed = available()
    if name not in installed:
        known = ", ".join(installed) or "none"
        why = f"no domain knowledge {name!r} is installed (installed: {known})"
        raise AgentFileError(source, "knowledge", why)
    return name


def _stall_counts(value: str, source: str) -> StallCounts:
    if value == "quiet":
        return "quiet"
    if value == "waiting":
        return "waiting"
    why = f"expected 'quiet' (seconds with nothing changing) or 'waiting', got {value!r}"
    raise AgentFileError(source, "scheduler.wait_stall_counts", why)


def _spread(value: float, source: str) -> float:
    if not (math.isfinite(value) and 0 <= value <= 4):
        raise AgentFileError(
            source, "scheduler.wait_stall_spread", f"expected a fraction from 0 to 4, got {value}"
        )
    return float(value)


def _wait_stall(value: float, source: str) -> float:
    if not (math.isfinite(value) and value > 0):
        raise AgentFileError(
            source, "scheduler.wait_stall", f"expected a number of seconds above 0, got {value}"
        )
    return float(value)


def _rtc_deadline(value: float, source: str) -> float:
    if not (math.isfinite(value) and value >= 1.0):
        raise AgentFileError(
            source, "scheduler.rtc_deadline", f"expected a number >= 1, got {value}"
        )
    return float(value)


class _Reader:
    """Typed access to the raw TOML, with errors that name the field."""

    def __init__(self, source: str, data: dict[str, Any]) -> None:
        self.source, self.data = source, data
        self.signature: dict[str, int] = {}  # the domain's predicates and functions
        self.private: frozenset[str] = frozenset()  # beliefs only the scheduler keeps
        self.functions: frozenset[str] = frozenset()  # the domain's functions

    def fail(self, where: str, reason: str) -> AgentFileError:
        return AgentFileError(self.source, where, reason)

    def get(self, table: dict[str, Any], key: str, tp: type, where: str) -> Any:
        if key not in table:
            raise self.fail(where, "missing")
        return self.check(table[key], tp, where)

    def opt(self, table: dict[str, Any], key: str, tp: type, default: Any, prefix: str = "") -> Any:
        where = f"{prefix}.{key}" if prefix else key
        return self.check(table[key], tp, where) if key in table else default

    def check(self, value: Any, tp: type, where: str) -> Any:
        if tp is float and isinstance(value, int) and not isinstance(value, bool):
            return float(value)
        if not isinstance(value, tp) or (tp is int and isinstance(value, bool)):
            raise self.fail(where, f"expected {tp.__name__}, got {type(value).__name__}")
        return value

    def natural(self, table: dict[str, Any], key: str, default: Any, prefix: str = "") -> Any:
        value = self.opt(table, key, int, default, prefix)
        if value is not None and value < 0:
            where = f"{prefix}.{key}" if prefix else key
            raise self.fail(where, f"expected an integer >= 0, got {value}")
        return value

    def number(
        self, table: dict[str, Any], key: str, default: float, where: str, low: float, high: float
    ) -> float:
        value = self.opt(table, key, float, default, where)
        if value is not default and not (math.isfinite(value) and low <= value <= high):
            span = f"[{low:g}, {high:g}]" if math.isfinite(high) else f">= {low:g}"
            raise self.fail(f"{where}.{key}", f"expected a finite number in {span}, got {value}")
        return float(value)

    def declared(self, belief: Belief, where: str, goal: bool = False) -> Belief:
        """Fail unless the domain declares `belief`'s predicate or function (with its
        arity), or, outside goals, the file lists it in `private_predicates`."""
        why = undeclared(belief, self.signature, self.private, goal, self.functions)
        if why:
            raise self.fail(where, why)
        return belief

    def table(self, data: dict[str, Any], key: str) -> dict[str, Any]:
        return cast(dict[str, Any], self.opt(data, key, dict, {}))

    def choice(
        self, table: dict[str, Any], key: str, options: tuple[str, ...], default: str, prefix: str
    ) -> str:
        value = self.opt(table, key, str, default, prefix)
        if value not in options:
            raise self.fail(f"{prefix}.{key}", f"expected one of {', '.join(options)}")
        return str(value)

    def belief(self, text: Any, where: str, goal: bool = False) -> Belief:
        try:
            belief = parse_belief(self.check(text, str, where))
        except (LiteralSyntaxError, ValueError) as exc:
            raise self.fail(where, str(exc)) from None
        return self.declared(belief, where, goal)

    def condition(self, raw: Any, where: str) -> Condition:
        clauses = self.check(raw, list, where)
        out = []
        for i, clause in enumerate(clauses):
            texts = self.check(clause, list, f"{where}[{i}]")
            try:
                literals = tuple(
                    parse_literal(self.check(t, str, f"{where}[{i}][{j}]"))
                    for j, t in enumerate(texts)
                )
            except (LiteralSyntaxError, ValueError) as exc:
                raise self.fail(f"{where}[{i}]", str(exc)) from None
            for j, lit in enumerate(literals):
                self.declared(lit.belief, f"{where}[{i}][{j}]")
            out.append(literals)
        return tuple(out)

    def desire(self, raw: Any, where: str) -> Desire:
        d = self.check(raw, dict, where)
        goal = tuple(
            self.belief(g, f"{where}.goal[{i}]", goal=True)
            for i, g in enumerate(self.get(d, "goal", list, f"{where}.goal"))
        )
        name = self.get(d, "name", str, f"{where}.name")
        together = self.opt(d, "together", str, "", where)
        if together and (not _JOINT.fullmatch(together) or together == name):
            raise self.fail(
                f"{where}.together",
                f"expected the name of a joint intention (letters, digits, _ and -, not"
                f" the desire's own name), got {together!r}",
            )
        return Desire(
            name=name,
            together=together,
            goal=goal,
            priority=self.number(d, "priority", 0.5, where, 0.0, 1.0),
            deadline=self.number(d, "deadline", NO_DEADLINE, where, 0.0, math.inf),
            precondition=self.condition(d.get("precondition", []), f"{where}.precondition"),
            context=self.condition(d.get("context", []), f"{where}.context"),
        )

    def rule(self, raw: Any, where: str) -> ReactiveRule:
        r = self.check(raw, dict, where)
        effects = tuple(
            self.effect(e, f"{where}.then[{i}]")
            for i, e in enumerate(self.get(r, "then", list, f"{where}.then"))
        )
        return ReactiveRule(
            condition=self.condition(self.get(r, "when", list, f"{where}.when"), f"{where}.when"),
            effects=effects,
            name=self.opt(r, "name", str, "", where),
        )

    def effect(self, raw: Any, where: str) -> RuleEffect:
        e = self.check(raw, dict, where)
        if len(e) != 1:
            raise self.fail(
                where, "one of add_belief, del_belief, add_desire, del_desire, boost, ask"
            )
        ((kind, value),) = e.items()
        if kind == "ask":
            return self.ask(value, f"{where}.ask")
        if kind in ("add_belief", "del_belief"):
            op = "ADD" if kind == "add_belief" else "DEL"
            return RuleEffect("belief", op, belief=self.belief(value, f"{where}.{kind}"))
        if kind in ("add_desire", "boost"):
            op = "ADD" if kind == "add_desire" else "BOOST"
            return RuleEffect("desire", op, desire=self.desire(value, f"{where}.{kind}"))
        if kind == "del_desire":
            name = self.check(value, str, f"{where}.del_desire")
            return RuleEffect("desire", "DEL", desire=Desire(name=name, goal=()))
        raise self.fail(where, f"unknown effect {kind!r}")

    def ask(self, raw: Any, where: str) -> RuleEffect:
        """An `ask = { agent = "{r}", add_belief = "(...)" }` effect (or `del_belief`):
        the file must name its group, which the request goes under."""
        a = self.check(raw, dict, where)
        if not self.opt(self.data, "group", str, ""):
            raise self.fail(where, "an ask goes under the agent's group: set `group`")
        agent = self.get(a, "agent", str, f"{where}.agent")
        if not _PLACEHOLDER.search(agent):
            try:
                validate_name(agent)
            except ValueError as exc:
                raise self.fail(f"{where}.agent", str(exc)) from None
        ops = [k for k in ("add_belief", "del_belief") if k in a]
        unknown = sorted(set(a) - {"agent", "add_belief", "del_belief"})
        if len(ops) != 1 or unknown:
            why = f"unknown key {unknown[0]!r}: " if unknown else ""
            raise self.fail(where, why + "an ask needs `agent` and one of add_belief, del_belief")
        belief = self.belief(a[ops[0]], f"{where}.{ops[0]}")
        if belief.kind != PREDICATE:
            raise self.fail(f"{where}.{ops[0]}", "an ask adds or deletes a predicate fact")
        op = "ADD" if ops[0] == "add_belief" else "DEL"
        return RuleEffect("ask", op, belief=belief, agent=agent)


_PLACEHOLDER = re.compile(r"\{\w+\}")


_JOINT = re.compile(r"[A-Za-z][A-Za-z0-9_\-]{0,62}")


def _domain_text(source: str, domain: Path) -> str:
    try:
        return domain.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise AgentFileError(source, "domain", f"cannot read {domain}: {exc}") from None
