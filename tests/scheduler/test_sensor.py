"""Sensors (`cbdi.sensor`): readings become belief additions and deletions through the
agent's request endpoint, checked against the domain (the scheduler's shell on the
in-memory bus)."""

from __future__ import annotations

import asyncio
import io

from cbdi import keys
from cbdi.bus import MemoryNetwork, request
from cbdi.runtime.log import Log
from cbdi.runtime.together import Together, TogetherService
from cbdi.sensor import Prototype, SensorLoop, run_sensor
from cbdi.wire.agent import AgentReply, AgentState, StateRequest
from cbdi_scheduler.agentfile import load_agent
from cbdi_scheduler.mind import Mind
from cbdi_scheduler.service import SchedulerSettings, scheduler_main
from tests_support import REPO

AGENT = REPO / "domains/recycling/agents/recycler.toml"


class Cells:
    """Senses which cells are free; the test sets what it reads."""

    def __init__(self, predicate: str = "free") -> None:
        self.prototype = Prototype(predicate, 1)
        self.now: list[tuple[str, ...]] = []
        self.reads = 0

    async def read(self) -> list[tuple[str, ...]]:
        self.reads += 1
        return self.now


def test_the_loop_tells_changes_once_and_leaves_refusals_until_the_reading_changes() -> None:
    loop = SensorLoop("robot1", Cells())
    assert loop.changes([("c_1_1",), ("c_2_2",), ("a", "b")]) == [
        (("c_1_1",), True),
        (("c_2_2",), True),
    ]
    loop.answered(("c_1_1",), True, AgentReply(accepted=True))
    loop.answered(("c_2_2",), True, AgentReply(accepted=False, reason="no"))
    assert loop.changes([("c_1_1",), ("c_2_2",)]) == []  # told, and refused: not again
    assert loop.changes([]) == [(("c_1_1",), False)]  # c_2_2's refusal is forgotten
    assert loop.changes([("c_2_2",)]) == [(("c_2_2",), True), (("c_1_1",), False)]
    assert loop.request(("c_2_2",), True).belief == "(free c_2_2)"


async def test_a_sensor_adds_and_deletes_beliefs_of_its_prototype() -> None:
    network = MemoryNetwork()
    settings = SchedulerSettings(agent="robot1", agent_file=str(AGENT), load_map=False)
    mind = Mind(load_agent(AGENT, "robot1"))
    shell = TogetherService("robot1/scheduler", settings, scheduler_main(mind, settings))
    task = asyncio.create_task(Together([shell], network, log_level="error").run())
    bus = network.bus()
    cells, typo = Cells(), Cells("fre")
    logged = io.StringIO()
    sensors = [
        asyncio.create_task(run_sensor(bus, "robot1", cells, rate=50.0)),
        asyncio.create_task(
            run_sensor(bus, "robot1", typo, rate=50.0, log=Log("s", stream=logged))
        ),
    ]
    state_key = keys.component_rpc("robot1", "scheduler", "state")

    async def believes(literal: str) -> bool:
        state = await request(bus, state_key, StateRequest(), AgentState)
        return literal in state.beliefs

    try:
        async with asyncio.timeout(10):
            while keys.alive("robot1/scheduler") not in network.tokens:
                await asyncio.sleep(0.01)
            cells.now = [("c_5_5",)]
            typo.now = [("c_5_5",)]
            while not await believes("(free c_5_5)"):
                await asyncio.sleep(0.02)
            cells.now = []
            while await believes("(free c_5_5)"):
                await asyncio.sleep(0.02)
            while "refused" not in logged.getvalue():
                await asyncio.sleep(0.02)
        assert "fre" in logged.getvalue() and logged.getvalue().count("refused") == 1
        assert not await believes("(fre c_5_5)")
        assert cells.reads > 2 and not any(t.done() for t in sensors)
    finally:
        for t in sensors:
            t.cancel()
        task.cancel()
        await asyncio.gather(task, *sensors, return_exceptions=True)
