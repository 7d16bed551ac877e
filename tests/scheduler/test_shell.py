"""The scheduler's service shell on the in-memory bus: requests change the mind, the
state endpoint tells it, and the next cycle acts on it."""

from __future__ import annotations

import asyncio

from cbdi import keys
from cbdi.bus import LogSink, MemoryNetwork, messages, request
from cbdi.runtime.together import Together, TogetherService
from cbdi.wire import encode
from cbdi.wire.agent import AgentReply, AgentRequest, AgentState, DesireEvent, StateRequest
from cbdi.wire.planner import SearchRequest
from cbdi_scheduler.agentfile import load_agent
from cbdi_scheduler.mind import Mind
from cbdi_scheduler.service import SchedulerSettings, scheduler_main
from tests.scheduler.test_mind import percepts
from tests_support import REPO

AGENT = REPO / "domains/recycling/agents/recycler.toml"


async def test_a_requested_desire_shows_in_the_state_and_is_pursued() -> None:
    network = MemoryNetwork()
    settings = SchedulerSettings(agent="robot1", agent_file=str(AGENT), load_map=False)
    mind = Mind(load_agent(AGENT, "robot1"))
    shell = TogetherService("robot1/scheduler", settings, scheduler_main(mind, settings))
    task = asyncio.create_task(Together([shell], network, log_level="error").run())
    bus = network.bus()
    try:
        async with asyncio.timeout(10):
            while keys.alive("robot1/scheduler") not in network.tokens:
                await asyncio.sleep(0.01)
        searches = messages(bus, keys.planner_requests("robot1"), SearchRequest, LogSink())
        events = messages(bus, keys.scheduler_desires("robot1"), DesireEvent, LogSink())
        ask = AgentRequest(
            from_agent="op",
            group="operator",
            op="add_desire",
            desire="visit",
            goal=["(in robot1 c_3_3)"],
            priority=0.9,
        )
        # Under a group's key, the group is the key's: naming another is refused.
        posing = await request(bus, keys.agent_request("robot1", "sensors"), ask, AgentReply)
        assert not posing.accepted and "asked under 'sensors'" in posing.reason
        rpc = keys.agent_request("robot1", "operator")
        assert (await request(bus, rpc, ask, AgentReply)).accepted
        state_key = keys.component_rpc("robot1", "scheduler", "state")
        state = await request(bus, state_key, StateRequest(beliefs=False), AgentState)
        assert [d.name for d in state.desires] == ["visit"] and state.intention is None
        await bus.publish(keys.world_percepts("robot1"), encode(percepts(0)))
        async with asyncio.timeout(10):
            _, search = await anext(searches)
            seen = [(await anext(events))[1].event for _ in range(2)]
        assert search.desire == "visit" and search.goal == [["in", "robot1", "c_3_3"]]
        assert seen == ["added", "activated"]
        state = await request(bus, state_key, StateRequest(), AgentState)
        assert state.intention is not None and state.intention.desire == "visit"
        assert "(in robot1 c_0_1)" in state.beliefs
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
