"""Scenario files: which map, which agents (and of which kind), and run settings.

A scenario lives in `domains/<domain>/scenarios/<name>.toml`:

    name = "courier"
    map = "../maps/floor.toml"         # relative to the scenario file (`clock` needs none)
    [run]
    simulator = "courier" # the domain's simulator the world hosts (cbdi.simulators)
    speed = 4.0          # simulated seconds per wall second
    seed = 1
    until = "done"       # or a number of simulated seconds
    max_time = 600.0     # simulated seconds after which a "done" run gives up
    lockstep = false
    [world]              # the simulator's own options (its `Options`; cbdi.simulator)
    [[agents]]
    name = "robot1"
    kind = "bdi"         # which services make up the agent: bdi (planner, scheduler and
    agent_file = "../agents/courier.toml"   # executor), or scripted (a domain's
    detection_depth = 1  # `cbdi scripted-agent` command in the executor's place)
"""

from __future__ import annotations

import math
import os
import tomllib
from dataclasses import dataclass, replace
from dataclasses import field as dataclass_field
from pathlib import Path
from typing import Any

from cbdi import keys
from cbdi.agentfile import AgentFileError, domain_actions, read_agent_file
from cbdi.errors import ConfigError
from cbdi.simulator import OptionValue, load_simulator, performed_actions, read_options

__all__ = [
    "AGENT_KINDS",
    "AgentEntry",
    "RunSettings",
    "Scenario",
    "agent_performers",
    "check_performed",
    "check_ranges",
    "check_until",
    "find_scenario",
    "load_scenario",
    "performer_actions",
]

# Components each agent kind runs; the scripted agent stands in for a whole BDI agent and
# takes the executor's place on the bus.
AGENT_KINDS: dict[str, tuple[str, ...]] = {
    "scripted": ("executor",),
    "bdi": ("planner", "scheduler", "executor"),
}


@dataclass(frozen=True)
class AgentEntry:
    """One agent of a scenario."""

    name: str
    kind: str = "scripted"
    detection_depth: int | None = None
    agent_file: Path | None = None  # a BDI agent's file (planner, scheduler)
    # Actions of this run's agent that its own process performs (`cbdi.robot`), besides
    # those its agent file names: the same agent, driven by its body in this scenario.
    performers: tuple[str, ...] = ()


@dataclass(frozen=True)
class RunSettings:
    """How a scenario runs; every field can be overridden from `cbdi up` flags."""

    speed: float = 4.0
    seed: int = 0
    until: str = "done"
    max_time: float = 600.0
    lockstep: bool = False
    mode: str = ""  # BDI agents' planning: online, offline ("": each agent file's)
    planning_speed: float = 0.0  # virtual time: expansions per simulated s (0: agent file's)
    simulator: str = ""  # the domain's simulator the world hosts (cbdi.simulators): needed


PLANNING_MODES = ("", "online", "offline")

# The lowest value of each numeric run setting; NaN and infinities never pass.
_LOWEST: dict[str, float] = {
    "speed": 0.0,
    "seed": 0,
    "max_time": 0.0,
    "planning_speed": 0.0,
}


def check_ranges(run: RunSettings) -> list[tuple[str, str]]:
    """Return `(field, reason)` for each numeric run setting out of its range."""
    problems = []
    for name, low in _LOWEST.items():
        value = getattr(run, name)
        if not (math.isfinite(value) and value >= low) or (name == "max_time" and value == 0):
            bound = "above 0" if name == "max_time" else f">= {low:g}"
            problems.append((name, f"expected a finite number {bound}, got {value!r}"))
    return problems


def check_until(value: object, where: str, field: str) -> str:
    """Return `until` as the launcher keeps it: `done` or a finite number of seconds > 0."""
    if value == "done":
        return "done"
    number = value
    if isinstance(value, str):
        try:
            number = float(value)
        except ValueError:
            number = None
    if isinstance(number, bool) or not isinstance(number, int | float):
        raise ConfigError(where, field, f"expected 'done' or seconds > 0, got {value!r}")
    if not (math.isfinite(number) and number > 0):
        raise ConfigError(where, field, f"expected 'done' or seconds > 0, got {value!r}")
    return str(value)


@dataclass(frozen=True)
class Scenario:
    """A loaded, validated scenario."""

    name: str
    path: Path
    map_path: Path | None  # None: a simulator with no map (`clock`)
    agents: tuple[AgentEntry, ...]
    run: RunSettings
    # The simulator's own options (the `[world]` table, `--option`), checked and typed.
    options: dict[str, OptionValue] = dataclass_field(default_factory=dict)

    def with_agents(self, count: int) -> Scenario:
        """Return the scenario with `count` agents: the first ones, or more of the last kind."""
        if count < 1:
            raise ConfigError("--agents", "agents", f"need at least 1 agent, got {count}")
        agents = list(self.agents[:count])
        template = self.agents[-1]
        names = {a.name for a in agents}
        n = len(agents)
        while len(agents) < count:
            n += 1
            name = f"robot{n}"
            if name not in names:
                agents.append(replace(template, name=name))
                names.add(name)
        return replace(self, agents=tuple(agents))


def _domain_scenarios(domains: Path) -> list[Path]:
    """Each domain's scenario folder under `domains`, by name."""
    found = sorted(domains.glob("*/scenarios"))
    return [p for p in found if p.is_dir()]


def _repo_scenarios() -> list[Path]:
    places = _domain_scenarios(Path.cwd() / "domains")
    env = os.environ.get("CBDI_DOMAINS")
    if env:
        places = _domain_scenarios(Path(env)) + places
    # An editable install sits in the repository: shared/src/cbdi/launcher/scenario.py.
    places += _domain_scenarios(Path(__file__).resolve().parents[4] / "domains")
    return places


def find_scenario(name_or_path: str) -> Path:
    """Resolve a scenario name (`paper-7x7`) or a path to its file."""
    path = Path(name_or_path)
    if path.suffix == ".toml" or path.exists():
        if not path.is_file():
            raise ConfigError(name_or_path, "scenario", "file not found")
        return path
    for folder in _repo_scenarios():
        candidate = folder / f"{name_or_path}.toml"
        if candidate.is_file():
            return candidate
    known = sorted({p.stem for f in _repo_scenarios() if f.is_dir() for p in f.glob("*.toml")})
    raise ConfigError(name_or_path, "scenario", f"no such scenario (known: {', '.join(known)})")


def load_scenario(path: Path) -> Scenario:
    """Load and validate a scenario file; errors name the file and the field."""
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ConfigError(str(path), "file", exc.strerror or str(exc)) from None
    except UnicodeDecodeError as exc:
        raise ConfigError(str(path), "file", f"not UTF-8 text (byte {exc.start})") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(str(path), "toml", str(exc)) from None
    where = str(path)
    map_path = None
    if "map" in data:
        map_path = (path.parent / _get(data, "map", str, where)).resolve()
        if not map_path.is_file():
            raise ConfigError(where, "map", f"map file {map_path} not found")
    agents = tuple(
        _agent(a, i, where, path.parent) for i, a in enumerate(_get(data, "agents", list, where))
    )
    if not agents:
        raise ConfigError(where, "agents", "a scenario needs at least one agent")
    if len({a.name for a in agents}) != len(agents):
        raise ConfigError(where, "agents", "agent names must be unique")
    run = _run(data.get("run", {}), where)
    if not run.simulator:
        raise ConfigError(where, "run.simulator", "missing: name the domain's simulator")
    simulator = load_simulator(run.simulator, f"{where}: run.simulator")
    if map_path is None and getattr(simulator, "needs_map", True):
        raise ConfigError(where, "map", f"missing: the {run.simulator!r} simulator needs a map")
    world = data.get("world", {})
    if not isinstance(world, dict):
        raise ConfigError(where, "world", "expected a table of the simulator's options")
    scenario = Scenario(
        name=str(data.get("name", path.stem)),
        path=path,
        map_path=map_path,
        agents=agents,
        run=run,
        options=read_options(simulator, world, where, "world."),
    )
    check_performed(scenario)
    return scenario


def agent_groups(scenario: Scenario) -> dict[str, str]:
    """The group of each BDI agent whose agent file asks other agents (a rule's `ask`):
    the run's security lets its scheduler ask the others under it, and no other
    agent's (docs/security.md)."""
    out = {}
    for agent in scenario.agents:
        if agent.kind == "bdi" and agent.agent_file is not None:
            data = read_agent_file(agent.agent_file, agent.name).data
            group = data.get("group", "")
            if isinstance(group, str) and group and _asks(data):
                out[agent.name] = group
    return out


def _asks(data: dict[str, Any]) -> bool:
    """Return whether an agent file's rules have an `ask` effect."""
    rules = data.get("rules", [])
    return isinstance(rules, list) and any(
        isinstance(e, dict) and "ask" in e
        for r in rules
        if isinstance(r, dict) and isinstance(r.get("then"), list)
        for e in r["then"]
    )


def agent_performers(agent: AgentEntry) -> tuple[str, ...]:
    """The actions `agent` leaves to performers: its agent file's and the scenario's."""
    if agent.kind != "bdi" or agent.agent_file is None:
        return ()
    named = read_agent_file(agent.agent_file, agent.name).performers
    return tuple(dict.fromkeys([*named, *agent.performers]))


def performer_actions(scenario: Scenario) -> list[str]:
    """The actions the scenario's BDI agents leave to performers (`cbdi.performer`)."""
    return sorted({a for agent in scenario.agents for a in agent_performers(agent)})


def check_performed(scenario: Scenario) -> None:
    """Refuse, before anything starts, a BDI agent whose domain has an action nobody
    performs: not the world (its simulator) and not a performer the agent file names."""
    run = scenario.run
    simulator = load_simulator(run.simulator, f"{scenario.path}: run.simulator")
    world_actions = performed_actions(simulator, scenario.options)
    who = f"the world ({run.simulator!r} simulator)"
    for agent in scenario.agents:
        if agent.kind != "bdi" or agent.agent_file is None:
            continue
        try:
            raw = read_agent_file(agent.agent_file, agent.name)
        except AgentFileError as exc:
            raise ConfigError(str(scenario.path), f"agents.{agent.name}", str(exc)) from None
        try:
            declared = domain_actions(raw.domain.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError) as exc:
            raise ConfigError(str(raw.domain), "file", f"cannot read it ({exc})") from None
        performed = {a.lower() for a in world_actions} | set(raw.performers)
        performed |= set(agent.performers)
        for action, line in sorted(declared.items(), key=lambda kv: kv[1]):
            if action not in performed:
                world = ", ".join(world_actions) or "nothing"
                raise ConfigError(
                    f"{raw.domain}:{line}",
                    f"action {action}",
                    f"nobody performs it: {who} "
                    f"performs {world}, and {raw.source} names no performer for it "
                    f'(`performers = ["{action}"]` with a `cbdi.performer` running)',
                )


def _get(data: dict[str, Any], field: str, tp: type, where: str) -> Any:
    if field not in data:
        raise ConfigError(where, field, "missing")
    value = data[field]
    if not isinstance(value, tp):
        raise ConfigError(where, field, f"expected {tp.__name__}, got {type(value).__name__}")
    return value


def _agent(raw: Any, index: int, where: str, base: Path) -> AgentEntry:
    field = f"agents[{index}]"
    if not isinstance(raw, dict):
        raise ConfigError(where, field, "expected a table")
    name = _get(raw, "name", str, where)
    try:
        keys.validate_name(name)
    except ValueError as exc:
        raise ConfigError(where, f"{field}.name", str(exc)) from None
    kind = raw.get("kind", "scripted")
    if kind not in AGENT_KINDS:
        raise ConfigError(
            where, f"{field}.kind", f"unknown kind {kind!r} (known: {sorted(AGENT_KINDS)})"
        )
    depth = raw.get("detection_depth")
    if depth is not None and (not isinstance(depth, int) or depth < 0):
        raise ConfigError(where, f"{field}.detection_depth", "expected an integer >= 0")
    agent_file = None
    if kind == "bdi":
        rel = raw.get("agent_file")
        if not isinstance(rel, str):
            raise ConfigError(where, f"{field}.agent_file", "a bdi agent needs its agent file")
        agent_file = (base / rel).resolve()
        if not agent_file.is_file():
            raise ConfigError(where, f"{field}.agent_file", f"no such file {agent_file}")
    performers = raw.get("performers", [])
    if not isinstance(performers, list) or (kind != "bdi" and performers):
        raise ConfigError(where, f"{field}.performers", "a bdi agent's list of action names")
    for i, action in enumerate(performers):
        try:
            keys.validate_name(action if isinstance(action, str) else "", "action")
        except ValueError as exc:
            raise ConfigError(where, f"{field}.performers[{i}]", str(exc)) from None
    return AgentEntry(
        name=name,
        kind=kind,
        detection_depth=depth,
        agent_file=agent_file,
        performers=tuple(a.lower() for a in performers),
    )


def _run(raw: Any, where: str) -> RunSettings:
    if not isinstance(raw, dict):
        raise ConfigError(where, "run", "expected a table")
    base = RunSettings()
    values: dict[str, Any] = {}
    for field, default in vars(base).items():
        if field not in raw:
            continue
        value = raw[field]
        if field == "until":
            value = check_until(value, where, "run.until")
        elif isinstance(default, float) and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if not isinstance(value, type(default)) or isinstance(value, bool) != (default is False):
            want, got = type(default).__name__, type(value).__name__
            raise ConfigError(where, f"run.{field}", f"expected {want}, got {got}")
        values[field] = value
    if values.get("mode", "") not in PLANNING_MODES:
        raise ConfigError(where, "run.mode", f"expected one of {', '.join(PLANNING_MODES[1:])}")
    unknown = set(raw) - set(vars(base))
    if unknown:
        raise ConfigError(where, "run", f"unknown settings: {', '.join(sorted(unknown))}")
    run = replace(base, **values)
    problems = check_ranges(run)
    if problems:
        field, reason = problems[0]
        raise ConfigError(where, f"run.{field}", reason)
    return run
