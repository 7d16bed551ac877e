"""Agent files, the parts every service of an agent reads (format in docs/agents.md).

The scheduler interprets beliefs, desires and rules (`cbdi_scheduler.agentfile`); the
planner needs the domain and the `[planning]` settings. Both read the file here, with
`{self}` replaced by the agent's name, so they always agree on what it says.
"""

from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from cbdi.errors import CbdiError

__all__ = [
    "MODES",
    "AgentFileError",
    "ExecutionSettings",
    "PlanningSettings",
    "RawAgentFile",
    "domain_functions",
    "domain_signature",
    "read_agent_file",
]

MODES = ("online", "offline")


class AgentFileError(CbdiError):
    """Reject an agent file, naming the file, the field and the reason."""

    code = "bad_agent_file"

    def __init__(self, path: str, field_name: str, reason: str) -> None:
        self.path, self.field, self.reason = path, field_name, reason
        super().__init__(f"{path}: {field_name}: {reason}")


@dataclass(frozen=True)
class PlanningSettings:
    """How the agent's planner searches (the continual planner's parameters)."""

    mode: str = "online"
    round_interval: float = 0.1
    expansions_per_round: int = 200
    plan_size_limit: int = 8
    min_commit_steps: int = 1
    forecast_horizon: int = 0
    empty_rounds: int = 10
    # The greedy rounds reach the goal facts one at a time, nearest first, as the offline
    # planner's goal agenda does: what lets the continual search finish on big maps.
    agenda: bool = False
    # Expansions one improving search may take (Alg. 2 lines 23-24) before it gives up
    # on the plan it tries to beat (0: no bound).
    improve_expansions: int = 3000
    backend: str = "cbdi"
    timeout: float = 30.0
    # Virtual time (lockstep): node expansions per simulated second of planning. The
    # planner gets this many per second of each epoch, online and offline alike.
    planning_speed: float = 2500.0


@dataclass(frozen=True)
class ExecutionSettings:
    """How the agent's executor starts steps (`[execution]`).

    `condition_wait`: simulated seconds a due step waits for its at-start and over-all
    conditions to hold (sensing catching up with what an action did) before it is
    refused; `condition_wait_for`: the same per action name.
    """

    condition_wait: float = 0.0
    condition_wait_for: tuple[tuple[str, float], ...] = ()

    def executor_args(self) -> list[str]:
        """The `cbdi-executor` flags that set these."""
        args = ["--condition-wait", repr(self.condition_wait)] if self.condition_wait else []
        for action, seconds in self.condition_wait_for:
            args += ["--condition-wait-for", f"{action}={seconds!r}"]
        return args


@dataclass(frozen=True)
class RawAgentFile:
    """The TOML of an agent file, its source, and the resolved, existing domain file."""

    data: dict[str, Any]
    source: str
    domain: Path
    planning: PlanningSettings
    # The domain's predicates that moving things change (a cell `free` of people and
    # robots): a goal that only such beliefs block is waited out, not given up.
    transient: tuple[str, ...] = ()
    # The domain's actions that performers carry out (code on the robot or beside it,
    # `cbdi.performer`) rather than the world: the executor sends them to the performer.
    performers: tuple[str, ...] = ()
    execution: ExecutionSettings = ExecutionSettings()


def read_agent_file(path: str | Path, agent: str) -> RawAgentFile:
    """Read the agent file at `path` for agent `agent` and check its common parts."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8").replace("{self}", agent)
    except OSError as exc:
        raise AgentFileError(str(p), "file", exc.strerror or str(exc)) from None
    except UnicodeDecodeError as exc:
        raise AgentFileError(str(p), "file", f"not UTF-8 text (byte {exc.start})") from None
    return parse_agent_text(text, str(p), p.parent)


def parse_agent_text(text: str, source: str, base: Path) -> RawAgentFile:
    """Parse agent-file `text` (`{self}` already replaced); paths relative to `base`."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise AgentFileError(source, "toml", str(exc)) from None
    domain = data.get("domain")
    if not isinstance(domain, str):
        raise AgentFileError(source, "domain", "missing or not a string")
    path = base / domain
    if not path.is_file():
        raise AgentFileError(source, "domain", f"no such file {path}")
    planning = _planning(data.get("planning", {}), source)
    transient = _transient(data, source, path)
    performers = _performers(data, source, path)
    execution = _execution(data.get("execution", {}), source, path)
    return RawAgentFile(data, source, path, planning, transient, performers, execution)


def _seconds(value: Any, source: str, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise AgentFileError(source, where, f"expected seconds, got {type(value).__name__}")
    if not (math.isfinite(value) and value >= 0):
        raise AgentFileError(source, where, "expected a finite number of seconds >= 0")
    return float(value)


def _execution(table: Any, source: str, domain: Path) -> ExecutionSettings:
    """Read `[execution]`: `condition_wait` and `condition_wait_for = { ACTION = s }`."""
    if not isinstance(table, dict):
        raise AgentFileError(source, "execution", "expected a table")
    known = ("condition_wait", "condition_wait_for")
    for key in table:
        if key not in known:
            raise AgentFileError(
                source, f"execution.{key}", f"unknown setting (known: {', '.join(known)})"
            )
    wait = _seconds(table.get("condition_wait", 0.0), source, "execution.condition_wait")
    per = table.get("condition_wait_for", {})
    if not isinstance(per, dict):
        raise AgentFileError(source, "execution.condition_wait_for", "expected a table")
    declared = domain_actions(_domain_text(domain, source)) if per else {}
    out = []
    for action, value in per.items():
        where = f"execution.condition_wait_for.{action}"
        if action.lower() not in declared:
            known_actions = ", ".join(sorted(declared)) or "none"
            raise AgentFileError(
                source, where, f"the domain has no action {action!r} (it has: {known_actions})"
            )
        out.append((action.lower(), _seconds(value, source, where)))
    return ExecutionSettings(wait, tuple(out))


def _performers(data: dict[str, Any], source: str, domain: Path) -> tuple[str, ...]:
    """Read `performers`: names of actions the domain declares."""
    names = data.get("performers", [])
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        raise AgentFileError(source, "performers", "expected a list of action names")
    declared = domain_actions(_domain_text(domain, source))
    for name in names:
        if name.lower() not in declared:
            known = ", ".join(sorted(declared)) or "none"
            raise AgentFileError(
                source, "performers", f"the domain has no action {name!r} (it has: {known})"
            )
    return tuple(n.lower() for n in names)


def _domain_text(domain: Path, source: str) -> str:
    try:
        return domain.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise AgentFileError(source, "domain", f"{domain}: cannot read it ({exc})") from None


def domain_actions(text: str) -> dict[str, int]:
    """Return the actions a PDDL domain declares, with the line each is declared on."""
    found: dict[str, int] = {}
    bare = _COMMENT.sub("", text)  # comments go, their lines stay
    for m in _ACTION.finditer(bare):
        found.setdefault(m.group(1).lower(), bare.count("\n", 0, m.start()) + 1)
    return found


def _transient(data: dict[str, Any], source: str, domain: Path) -> tuple[str, ...]:
    """Read `transient_predicates`: names of predicates the domain declares."""
    names = data.get("transient_predicates", [])
    if not isinstance(names, list):
        raise AgentFileError(source, "transient_predicates", "expected a list of predicate names")
    if not names:
        return ()
    try:
        declared = domain_signature(domain.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise AgentFileError(source, "domain", f"cannot read {domain}: {exc}") from None
    out = []
    for i, name in enumerate(names):
        where = f"transient_predicates[{i}]"
        if not isinstance(name, str) or not name:
            raise AgentFileError(source, where, "expected a predicate name")
        if name.lower() not in declared:
            raise AgentFileError(source, where, f"the domain has no predicate {name!r}")
        out.append(name.lower())
    return tuple(out)


# The lower bound of each numeric planning setting (NaN and infinities never pass).
_LIMITS = (
    ("round_interval", 0.0, "expected a finite number of seconds >= 0"),
    ("expansions_per_round", 0, "expected an integer >= 0 (0: no bound)"),
    ("plan_size_limit", 0, "expected an integer >= 0 (0: no limit)"),
    ("min_commit_steps", 0, "expected an integer >= 0"),
    ("forecast_horizon", 0, "expected an integer >= 0 (0: the whole plan)"),
    ("empty_rounds", 0, "expected an integer >= 0"),
    ("improve_expansions", 0, "expected an integer >= 0 (0: no bound)"),
    ("timeout", 0.0, "expected a finite number of seconds above 0"),
)


def _planning(table: Any, source: str) -> PlanningSettings:
    if not isinstance(table, dict):
        raise AgentFileError(source, "planning", "expected a table")
    defaults = PlanningSettings()
    known = {f.name for f in fields(PlanningSettings)}
    values: dict[str, Any] = {}
    for key, value in table.items():
        if key not in known:
            raise AgentFileError(
                source, f"planning.{key}", f"unknown setting (known: {', '.join(sorted(known))})"
            )
        want = type(getattr(defaults, key))
        if want is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if not isinstance(value, want) or isinstance(value, bool) != (want is bool):
            raise AgentFileError(
                source, f"planning.{key}", f"expected {want.__name__}, got {type(value).__name__}"
            )
        values[key] = value
    settings = PlanningSettings(**values)
    if not (math.isfinite(settings.planning_speed) and settings.planning_speed > 0):
        raise AgentFileError(
            source, "planning.planning_speed", "expected a finite number of expansions above 0"
        )
    for key, low, reason in _LIMITS:
        value = getattr(settings, key)
        if not (math.isfinite(value) and value >= low) or (key == "timeout" and value == 0):
            raise AgentFileError(source, f"planning.{key}", f"{reason}, got {value!r}")
    if settings.mode not in MODES:
        raise AgentFileError(source, "planning.mode", f"expected one of {', '.join(MODES)}")
    return settings


_TOKEN = re.compile(r";[^\n]*|\(|\)|[^\s();]+")
_COMMENT = re.compile(r";[^\n]*")
_ACTION = re.compile(r"\(\s*:(?:durative-)?action\s+([^\s();]+)", re.IGNORECASE)


def domain_signature(text: str) -> dict[str, int]:
    """Return the predicates and functions a PDDL domain declares, with their arities.

    A scan of the `(:predicates ...)` and `(:functions ...)` sections only: enough for
    an agent file's check that its beliefs, rules and goals name what the domain has,
    without the common library depending on the planner's parser.
    """
    return {name: arity for _section, name, arity in _declared(text)}


def domain_functions(text: str) -> frozenset[str]:
    """Return the names of the functions (numeric fluents) a PDDL domain declares: what
    a belief `(= (name ...) value)` may name, and a plain atom may not."""
    return frozenset(name for section, name, _ in _declared(text) if section == ":functions")


def _declared(text: str) -> list[tuple[str, str, int]]:
    """Every `(:predicates ...)` and `(:functions ...)` entry: (section, name, arity)."""
    tokens = [t.lower() for t in _TOKEN.findall(text) if not t.startswith(";")]
    found: list[tuple[str, str, int]] = []
    i = 0
    while i < len(tokens) - 1:
        if tokens[i] == "(" and tokens[i + 1] in (":predicates", ":functions"):
            i = _declarations(tokens, i + 2, tokens[i + 1], found)
        else:
            i += 1
    return found


def _declarations(
    tokens: list[str], i: int, section: str, found: list[tuple[str, str, int]]
) -> int:
    """Read `(name ?a - t ?b)...` up to the section's `)`; return the index after it."""
    while i < len(tokens) and tokens[i] != ")":
        if tokens[i] == "(" and i + 1 < len(tokens):
            j = i + 2
            while j < len(tokens) and tokens[j] not in ("(", ")"):
                j += 1
            arity = sum(t.startswith("?") for t in tokens[i + 2 : j])
            found.append((section, tokens[i + 1], arity))
            i = j
        i += 1
    return i + 1
