"""Agent files, the parts every service of an agent reads (format in docs/agents.md).

The scheduler interprets beliefs, desires and rules (`cbdi_scheduler.agentfile`); the
planner needs the domain and the `[planning]` settings. Both read the file here, with
`{self}` replaced by the agent's name, so they always agree on what it says.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from cbdi.errors import CbdiError

__all__ = ["MODES", "AgentFileError", "PlanningSettings", "RawAgentFile", "read_agent_file"]

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
    # Expansions one improving search may take (Alg. 2 lines 23-24) before it gives up
    # on the plan it tries to beat (0: no bound).
    improve_expansions: int = 3000
    backend: str = "cbdi"
    timeout: float = 30.0
    # Virtual time (lockstep): node expansions per simulated second of planning. The
    # planner gets this many per second of each epoch, online and offline alike.
    planning_speed: float = 2500.0


@dataclass(frozen=True)
class RawAgentFile:
    """The TOML of an agent file, its source, and the resolved, existing domain file."""

    data: dict[str, Any]
    source: str
    domain: Path
    planning: PlanningSettings


def read_agent_file(path: str | Path, agent: str) -> RawAgentFile:
    """Read the agent file at `path` for agent `agent` and check its common parts."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8").replace("{self}", agent)
    except OSError as exc:
        raise AgentFileError(str(p), "file", exc.strerror or str(exc)) from None
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
    return RawAgentFile(data, source, path, _planning(data.get("planning", {}), source))


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
    if settings.improve_expansions < 0:
        raise AgentFileError(source, "planning.improve_expansions", "expected 0 or more")
    if settings.mode not in MODES:
        raise AgentFileError(source, "planning.mode", f"expected one of {', '.join(MODES)}")
    return settings
