"""Which services a scenario runs, with which arguments: one list for every way of running.

`cbdi up` turns it into supervised processes (`specs.run_specs`), `cbdi compose` into compose
services. So both start the same world, with the same `--member` for every component of
every agent (the start barrier), and the same agent services.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from cbdi import keys
from cbdi.agentfile import read_agent_file
from cbdi.errors import CbdiError
from cbdi.launcher.scenario import AGENT_KINDS, AgentEntry, Scenario, agent_performers
from cbdi.robot import MEMBER as ROBOT_MEMBER

__all__ = ["ServicePlan", "agent_of", "plan_services"]

# A path argument as the service will see it (the host's path, or one in a container).
PathOf = Callable[[Path], str]

_BDI_SCRIPTS = {
    "planner": ("cbdi-planner-agent", "cbdi_planner.agent.cli"),
    "scheduler": ("cbdi-scheduler", "cbdi_scheduler.cli"),
    "executor": ("cbdi-executor", "cbdi_executor.cli"),
}


@dataclass(frozen=True)
class ServicePlan:
    """One service of a run: its id (`world`, `robot1/planner`), console script and args."""

    service: str
    script: str
    module: str  # run as `python -m module` when the script is not installed
    args: tuple[str, ...]


def agent_of(service: str) -> str:
    """Return the agent a service id belongs to ('' for router, monitor and world)."""
    return service.split("/", 1)[0] if "/" in service else ""


def plan_services(
    scenario: Scenario, listen: str, record: str = "", path_of: PathOf = str
) -> list[ServicePlan]:
    """Return the run's services in start order: router, monitor (when `record`), world,
    then each agent's components. The router listens on `listen`."""
    plans = [ServicePlan("router", "cbdi", "cbdi.cli", ("router", "--listen", listen))]
    if record:
        monitor = ServicePlan("monitor", "cbdi-monitor", "cbdi_monitor.cli", ("--output", record))
        plans.append(monitor)
    world = ServicePlan("world", "cbdi-world", "cbdi_world.cli", world_args(scenario, path_of))
    plans.append(world)
    for agent in scenario.agents:
        for component in AGENT_KINDS[agent.kind]:
            plans.append(_agent_plan(agent, component, scenario, path_of))
    return plans


def world_args(scenario: Scenario, path_of: PathOf = str) -> tuple[str, ...]:
    """Return the world's arguments: the map, the simulator and its options, the run
    settings, agents and members."""
    run = scenario.run
    args = ["--map", path_of(scenario.map_path)] if scenario.map_path is not None else []
    args += ["--speed", str(run.speed)]
    args += ["--seed", str(run.seed)]
    if run.until == "done":
        args += ["--max-time", str(run.max_time), "--stop-when-done"]
    else:
        args += ["--max-time", run.until, "--no-stop-when-done"]
    args += ["--lockstep" if run.lockstep else "--no-lockstep"]
    args += ["--simulator", run.simulator]
    for key, value in sorted(scenario.options.items()):
        args += ["--option", f"{key}={_option_text(value)}"]
    for agent in scenario.agents:
        depth = f":{agent.detection_depth}" if agent.detection_depth is not None else ""
        args += ["--agent", f"{agent.name}{depth}"]
    for agent in scenario.agents:  # every component the world waits for, from epoch -1
        for component in AGENT_KINDS[agent.kind]:
            args += ["--member", keys.member(agent.name, component)]
        # The robot's own process (cbdi.robot) performs some of its actions: in lockstep
        # it is a member too, started by the user, waited for from epoch -1.
        if run.lockstep and agent_performers(agent):
            args += ["--member", keys.member(agent.name, ROBOT_MEMBER)]
    return tuple(args)


def _option_text(value: object) -> str:
    """A simulator option as `--option` reads it back (`true`/`false` for booleans)."""
    return str(value).lower() if isinstance(value, bool) else str(value)


def _agent_plan(
    agent: AgentEntry, component: str, scenario: Scenario, path_of: PathOf
) -> ServicePlan:
    service = keys.service_id(component, agent.name)
    run = scenario.run
    if agent.kind == "bdi":
        args = ["--agent", agent.name]
        if component != "executor":
            assert agent.agent_file is not None  # load_scenario requires it of a bdi agent
            args += ["--agent-file", path_of(agent.agent_file)]
        if component == "planner" and run.mode:
            args += ["--planning", run.mode]
        if component == "planner" and run.planning_speed > 0:
            args += ["--planning-speed", str(run.planning_speed)]
        if component == "executor":
            assert agent.agent_file is not None
            raw = read_agent_file(agent.agent_file, agent.name)
            for action in agent_performers(agent):
                args += ["--performer", action]
            args += raw.execution.executor_args()
        return ServicePlan(service, *_BDI_SCRIPTS[component], tuple(args))
    if agent.kind == "scripted":  # a domain's scripted robot (it asks the world its map)
        return ServicePlan(service, "cbdi", "cbdi.cli", ("scripted-agent", "--agent", agent.name))
    raise CbdiError(f"agent kind {agent.kind!r} has no services")
