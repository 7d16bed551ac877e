"""Scenario files: which map, which agents (and of which kind), and run settings.

A scenario lives in `domains/recycling/scenarios/<name>.toml`:

    name = "paper-7x7"
    map = "../maps/paper-7x7.toml"     # relative to the scenario file
    [run]
    speed = 4.0          # simulated seconds per wall second
    seed = 1
    until = "done"       # or a number of simulated seconds
    max_time = 600.0     # simulated seconds after which a "done" run gives up
    lockstep = false
    move_step = 4        # the paper's situation: people's pace, detection depth,
    det_area = 1         #   and how many litter items are known at the start
    known_litter = 2
    people_phase = true  # the seed also picks where on their loop people start,
    people_jitter = 1    #   a +-1 epoch jitter of their steps,
    duration_noise = 0.0 #   a 0..F stretch of action durations (experiments),
    failure_probability = 0.0  # and actions failing at random (experiments)
    binding = "recycling" # how the world performs the agents' PDDL actions
    [[agents]]
    name = "robot1"
    kind = "scripted"    # which services make up the agent: scripted, or bdi with
    # agent_file = "../agents/recycler.toml"   (planner, scheduler and executor)
    detection_depth = 1
"""

from __future__ import annotations

import math
import os
import tomllib
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from cbdi import keys
from cbdi.agentfile import AgentFileError, domain_actions, read_agent_file
from cbdi.chance import chance_problems
from cbdi.errors import ConfigError
from cbdi.plugins import load_binding
from cbdi.simulator import load_simulator

__all__ = [
    "AGENT_KINDS",
    "AgentEntry",
    "RunSettings",
    "Scenario",
    "check_chance",
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


@dataclass(frozen=True)
class RunSettings:
    """How a scenario runs; every field can be overridden from `cbdi up` flags."""

    speed: float = 4.0
    seed: int = 0
    until: str = "done"
    max_time: float = 600.0
    lockstep: bool = False
    move_step: int = 0  # people step every N epochs (0: the map's)
    det_area: int = -1  # the agents' detection depth (-1: the map's or the agent's)
    known_litter: int = -1  # litter items known at the start (-1: the map's)
    spawn: float = -1.0  # probability of new litter per epoch (-1: the map's)
    mode: str = ""  # BDI agents' planning: online, offline ("": each agent file's)
    planning_speed: float = 0.0  # virtual time: expansions per simulated s (0: agent file's)
    people_phase: bool = False  # people start at a seeded cell of their loop
    people_jitter: int = 0  # people step up to N epochs early or late (seeded)
    duration_noise: float = 0.0  # actions last a seeded 0..F longer (whole epochs)
    failure_probability: float = 0.0  # accepted actions fail at their end with this chance
    binding: str = "recycling"  # how the world performs PDDL actions (cbdi.bindings)
    simulator: str = ""  # a domain's simulator the world hosts (cbdi.simulators; "": grid)


PLANNING_MODES = ("", "online", "offline")


def check_chance(run: RunSettings) -> list[tuple[str, str]]:
    """Return `(field, reason)` for each of the world's chance options out of range."""
    return chance_problems(run.people_jitter, run.duration_noise, run.failure_probability)


# The lowest value of each numeric run setting; NaN and infinities never pass.
_LOWEST: dict[str, float] = {
    "speed": 0.0,
    "seed": 0,
    "max_time": 0.0,
    "move_step": 0,
    "det_area": -1,
    "known_litter": -1,
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
    if not (run.spawn == -1 or 0 <= run.spawn <= 1):
        problems.append(("spawn", f"expected a probability in [0, 1] (or -1), got {run.spawn!r}"))
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
    map_path: Path
    agents: tuple[AgentEntry, ...]
    run: RunSettings

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
    """Each domain's scenario folder under `domains` (recycling first, then by name)."""
    found = sorted(domains.glob("*/scenarios"), key=lambda p: (p.parent.name != "recycling", p))
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
    map_rel = _get(data, "map", str, where)
    map_path = (path.parent / map_rel).resolve()
    if not map_path.is_file():
        raise ConfigError(where, "map", f"map file {map_path} not found")
    agents = tuple(
        _agent(a, i, where, path.parent) for i, a in enumerate(_get(data, "agents", list, where))
    )
    if not agents:
        raise ConfigError(where, "agents", "a scenario needs at least one agent")
    if len({a.name for a in agents}) != len(agents):
        raise ConfigError(where, "agents", "agent names must be unique")
    scenario = Scenario(
        name=str(data.get("name", path.stem)),
        path=path,
        map_path=map_path,
        agents=agents,
        run=_run(data.get("run", {}), where),
    )
    check_performed(scenario)
    return scenario


def performer_actions(scenario: Scenario) -> list[str]:
    """The actions the scenario's BDI agents leave to performers (`cbdi.performer`)."""
    found: set[str] = set()
    for agent in scenario.agents:
        if agent.kind == "bdi" and agent.agent_file is not None:
            found.update(read_agent_file(agent.agent_file, agent.name).performers)
    return sorted(found)


def check_performed(scenario: Scenario) -> None:
    """Refuse, before anything starts, a BDI agent whose domain has an action nobody
    performs: not the world (its binding) and not a performer the agent file names."""
    run = scenario.run
    if run.simulator:
        world_actions = load_simulator(run.simulator, f"{scenario.path}: run.simulator").actions
        who = f"the world ({run.simulator!r} simulator)"
    else:
        world_actions = load_binding(run.binding, f"{scenario.path}: run.binding").actions
        who = f"the world ({run.binding!r} binding)"
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
    return AgentEntry(name=name, kind=kind, detection_depth=depth, agent_file=agent_file)


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
    problems = check_chance(run) + check_ranges(run)
    if problems:
        field, reason = problems[0]
        raise ConfigError(where, f"run.{field}", reason)
    return run
