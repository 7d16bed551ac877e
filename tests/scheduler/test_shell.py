"""The scheduler's service shell on the in-memory bus: requests change the mind, the
state endpoint tells it, and the next cycle acts on it."""

from __future__ import annotations

import asyncio

import pytest

import cbdi_scheduler.service as scheduler_service
from cbdi import keys
from cbdi.bus import LogSink, MemoryNetwork, messages, request
from cbdi.bus.typed import serve
from cbdi.runtime.together import Together, TogetherService
from cbdi.wire import encode
from cbdi.wire.agent import (
    ActionStatus,
    AgentReply,
    AgentRequest,
    AgentState,
    DesireEvent,
    StateRequest,
)
from cbdi.wire.planner import SearchRequest
from cbdi.wire.world import EpochAck, Tick, WorldInfo, WorldInfoRequest
from cbdi_scheduler.agentfile import load_agent
from cbdi_scheduler.mind import Mind
from cbdi_scheduler.service import SchedulerSettings, scheduler_main
from tests.scheduler.test_mind import percepts
from tests_support import REPO, grid_info

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


async def test_a_scheduler_started_before_its_world_waits_for_it_and_keeps_lockstep(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """An agent may start long before its world (another project, another machine): its
    scheduler waits for the world's map and members however long that takes, and an
    input that comes before the world's first tick does not make it take a lockstep run
    for a real-time one (it acks the epochs)."""
    monkeypatch.setattr(scheduler_service, "MAP_WAIT", 0.2)
    network = MemoryNetwork()
    settings = SchedulerSettings(agent="robot1", agent_file=str(AGENT))
    mind = Mind(load_agent(AGENT, "robot1"))
    shell = TogetherService("robot1/scheduler", settings, scheduler_main(mind, settings))
    bus = network.bus()
    acks = messages(bus, keys.epoch_ack("robot1", "scheduler"), EpochAck, LogSink())
    task = asyncio.create_task(Together([shell], network, log_level="error").run())
    try:
        # Several waits of the world go by (it is not there): no `ready` yet.
        await asyncio.sleep(1.0)
        early = asyncio.ensure_future(anext(acks))
        await asyncio.sleep(0.2)
        assert not early.done()
        # An input before the world's first tick (the executor says it is idle).
        status = ActionStatus(
            agent="robot1", plan_id="p", step_id="s", action="move", status="cancelled",
            reason="", time=0.0,
        )  # fmt: skip
        await bus.publish(keys.executor_status("robot1"), encode(status))
        info = grid_info(4, 3, map_name="room", members=["robot1/scheduler"], lockstep=True)

        async def answer(key: str, req: WorldInfoRequest) -> WorldInfo:
            return info

        world = asyncio.create_task(
            serve(bus, keys.world_rpc("info"), WorldInfoRequest, answer, LogSink())
        )
        async with asyncio.timeout(30):
            _, ready = await early
            assert (ready.epoch, ready.stage) == (-1, "ready")
            tick = Tick(epoch=0, time=0.0, epoch_duration=1.0, speed=0.0, lockstep=True)
            await bus.publish(keys.world_stream("clock"), encode(tick))
            await bus.publish(keys.world_percepts("robot1"), encode(percepts(0)))
            while (ack := (await anext(acks))[1]).epoch < 0:
                pass
        assert (ack.epoch, ack.stage) == (0, "beliefs")
        world.cancel()
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
