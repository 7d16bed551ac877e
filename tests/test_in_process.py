"""Every service shell of a BDI run in one process, on the in-memory bus (issue 12).

The world, and the planner, scheduler and executor of each agent, run as their own
asyncio services (`cbdi.runtime.together`) on endpoints of one `MemoryNetwork`, in
lockstep, flat out, with a manual clock that never moves: nothing but the epochs' order
drives them. Twice the same run gives the same request trace; so does the same scenario
over real Zenoh with one process per service.
"""

from __future__ import annotations

import asyncio
import json

import pytest

from cbdi import keys
from cbdi.agentfile import read_agent_file
from cbdi.bus import LogSink, MemoryNetwork, messages
from cbdi.clock import ManualClock
from cbdi.runtime.together import Together, TogetherService
from cbdi.wire.common import RunFinished
from cbdi_executor.service import ExecutorSettings, executor_main
from cbdi_planner.agent.service import PlannerSettings, planner_main
from cbdi_planner.pddl import parse_domain
from cbdi_scheduler.agentfile import load_agent
from cbdi_scheduler.mind import Mind
from cbdi_scheduler.service import SchedulerSettings, scheduler_main
from cbdi_world.service import WorldSettings, build_world, world_main
from tests_support import REPO, cbdi_up

MAP = str(REPO / "domains/recycling/maps/paper-7x7.toml")
AGENT_FILE = str(REPO / "domains/recycling/agents/recycler.toml")


def agent_services(name: str) -> list[TogetherService]:
    raw = read_agent_file(AGENT_FILE, name)
    domain = parse_domain(raw.domain.read_text(encoding="utf-8"), str(raw.domain))
    planner = PlannerSettings(agent=name, agent_file=AGENT_FILE)
    scheduler = SchedulerSettings(agent=name, agent_file=AGENT_FILE)
    executor = ExecutorSettings(agent=name)
    mind = Mind(load_agent(AGENT_FILE, name))
    return [
        TogetherService(f"{name}/planner", planner, planner_main(planner, domain, raw)),
        TogetherService(f"{name}/scheduler", scheduler, scheduler_main(mind, scheduler)),
        TogetherService(f"{name}/executor", executor, executor_main(executor)),
    ]


async def run_together(agents: list[str], seed: int) -> RunFinished:
    """Run the paper's map to its end in one process; return the world's last word."""
    members = tuple(f"{a}/{c}" for a in agents for c in ("planner", "scheduler", "executor"))
    settings = WorldSettings(
        simulator="recycling",
        map=MAP,
        agent=tuple(agents),
        speed=0.0,
        lockstep=True,
        seed=seed,
        max_time=300.0,
        member=members,
        option=("people_phase=true", "people_jitter=1"),  # as the paper-7x7 scenario
    )
    world = TogetherService("world", settings, world_main(build_world(settings), ManualClock()))
    services = [world, *(s for a in agents for s in agent_services(a))]
    network = MemoryNetwork()
    together = Together(services, network)
    ended = messages(network.bus(), keys.world_stream("events"), RunFinished, LogSink())

    async def watch() -> RunFinished:
        _, finished = await anext(ended)
        together.stop()
        return finished

    async with asyncio.timeout(300):
        watcher = asyncio.create_task(watch())
        codes = await together.run()
        finished = await watcher
    assert all(code == 0 for code in codes.values()), codes
    assert not finished.stalls, finished.stalls
    return finished


@pytest.mark.e2e
async def test_all_shells_in_one_process_repeat_and_match_real_zenoh() -> None:
    first = await run_together(["robot1"], seed=1)
    again = await run_together(["robot1"], seed=1)
    assert first.reason == "done" and first.requests > 0
    assert (again.trace_digest, again.epoch) == (first.trace_digest, first.epoch)
    other = await run_together(["robot1"], seed=3)
    assert other.trace_digest != first.trace_digest
    # One process per service over real Zenoh: the same run.
    result = cbdi_up("paper-7x7", "--seed", "1", "--speed", "0", "--json", "--quiet")
    assert result.returncode == 0, result.stderr[-2000:]
    summary = json.loads(result.stdout)
    assert (summary["trace_digest"], summary["epochs"]) == (first.trace_digest, first.epoch)


async def test_three_agents_in_one_process_repeat() -> None:
    runs = [await run_together(["robot1", "robot2", "robot3"], seed=2) for _ in range(2)]
    assert runs[0].reason == "done"
    assert runs[0].trace_digest == runs[1].trace_digest
