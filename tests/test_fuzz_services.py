"""Fuzz every service shell on the in-memory bus with messages of every wire type.

Hypothesis builds messages of every wire type (valid, and with fields out of their
ranges: the types say "int", the wire says "0 to 1000"), then some are mangled (a field
dropped, replaced by junk, or the schema tag of another type). Each service gets them on
every key it reads and on every request endpoint it serves. No service may die or crash
in a handler; the world and the scheduler still answer a valid request afterwards (the
planner and the executor may have been put in lockstep by a fuzzed Tick, and then wait
for epochs no world sends here).
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import warnings
from typing import Any

import msgpack
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_bad_input import AGENT_FILE, MAP, alone

import cbdi.wire.agent
import cbdi.wire.common
import cbdi.wire.planner
import cbdi.wire.world  # noqa: F401  (every wire type registered)
from cbdi import keys
from cbdi.agentfile import read_agent_file
from cbdi.clock import ManualClock
from cbdi.errors import CbdiError
from cbdi.runtime.together import TogetherService
from cbdi.wire import decode_any, encode
from cbdi.wire.agent import AgentState, StateRequest
from cbdi.wire.base import Message
from cbdi.wire.common import ErrorReply
from cbdi.wire.world import WorldInfo, WorldInfoRequest
from cbdi_executor.service import ExecutorSettings, executor_main
from cbdi_monitor.schemas import wire_classes
from cbdi_planner.agent.service import PlannerSettings, planner_main
from cbdi_planner.pddl import parse_domain
from cbdi_scheduler.agentfile import load_agent
from cbdi_scheduler.mind import Mind
from cbdi_scheduler.service import SchedulerSettings, scheduler_main
from cbdi_world.service import WorldSettings, build_world, world_main

A = "robot1"
STREAMS = [
    keys.world_stream("clock"),
    keys.world_percepts(A),
    keys.world_outcomes(A),
    keys.planner_requests(A),
    keys.planner_plans(A),
    keys.planner_status(A),
    keys.scheduler_beliefs(A),
    keys.scheduler_plans(A),
    keys.scheduler_arrest(A),
    keys.scheduler_claims("robot2"),
    keys.executor_status(A),
    keys.executor_arrested(A),
    keys.epoch_ack(A, "executor"),
    keys.epoch_ack(A, "planner"),
    keys.epoch_ack(A, "scheduler"),
    keys.component_rpc(A, "performer", "move") + "/outcomes",
]
ENDPOINTS = [
    keys.world_rpc("act"),
    keys.world_act(A),
    keys.world_rpc("stats"),
    keys.world_rpc("info"),
    keys.world_rpc("clock"),
    keys.component_rpc(A, "scheduler", "request"),
    keys.component_rpc(A, "scheduler", "state"),
    keys.component_rpc(A, "executor", "stop"),
]
JUNK = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(2**63), max_value=2**64 - 1),
    st.floats(),
    st.text(max_size=20),
    st.lists(st.integers(-5, 5), max_size=3),
    st.dictionaries(st.text(max_size=3), st.integers(), max_size=2),
)


def fuzzed(count: int) -> list[bytes]:
    """`count` payloads: messages of every wire type, valid or not, some mangled."""
    # The wire types themselves (not message classes other tests happen to import), so
    # the same examples come whatever ran before.
    classes = [c for _, c in sorted(wire_classes().items()) if c.__module__.startswith("cbdi.wire")]
    tags = [cls.__struct_config__.tag for cls in classes]
    found: list[bytes] = []

    @settings(
        max_examples=count,
        derandomize=True,
        database=None,
        deadline=None,
        suppress_health_check=list(HealthCheck),
    )
    @given(st.sampled_from(classes).flatmap(st.builds), st.integers(0, 3), st.data())
    def collect(msg: Message, how: int, data: st.DataObject) -> None:
        try:
            fields: dict[str, Any] = msgpack.unpackb(encode(msg), strict_map_key=False)
        except (OverflowError, ValueError, TypeError):  # an int msgpack cannot carry, a
            return  # default left unbuilt: nothing to send
        names = sorted(k for k in fields if k != "schema")
        if how == 1 and names:
            del fields[data.draw(st.sampled_from(names))]
        elif how == 2 and names:
            fields[data.draw(st.sampled_from(names))] = data.draw(JUNK)
        elif how == 3:
            fields["schema"] = data.draw(st.sampled_from(tags))
        with contextlib.suppress(OverflowError, ValueError, TypeError):
            found.append(msgpack.packb(fields))

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        collect()
    return found


@functools.cache
def payloads() -> list[bytes]:
    return fuzzed(1000)


async def fuzz(service: TogetherService, check: Any) -> None:
    async with alone(service) as (bus, ctx):
        for i, payload in enumerate(payloads()):
            await bus.publish(STREAMS[i % len(STREAMS)], payload)
            if i % 4 == 0:
                with contextlib.suppress(CbdiError, TimeoutError):  # nobody serves it here
                    await bus.request(ENDPOINTS[i % len(ENDPOINTS)], payload, timeout=2.0)
            if i % 50 == 0:
                await asyncio.sleep(0.01)  # let the service's loop take them in
        await asyncio.sleep(0.2)
        await check(bus)
        assert ctx.counters["handler_crash"] == 0
        refused = sum(n for k, n in ctx.counters.items() if k.startswith("bad_input"))
        assert refused > 20, dict(ctx.counters)  # the fuzz reached it: much was refused
        print(service.service, "refused", refused, "of", len(payloads()), "payloads")


def _agent() -> Any:
    return read_agent_file(AGENT_FILE, A)


async def test_the_world_survives_fuzzing() -> None:
    world_settings = WorldSettings(simulator="recycling", map=MAP, agent=(A,), wait_agents=0)
    world = build_world(world_settings)
    shell = TogetherService("world", world_settings, world_main(world, ManualClock()))

    async def check(bus: Any) -> None:
        reply = await bus.request(keys.world_rpc("info"), encode(WorldInfoRequest()))
        assert isinstance(decode_any(reply, (WorldInfo, ErrorReply)), WorldInfo)

    await fuzz(shell, check)


@pytest.mark.parametrize("planning", ["online", "offline"])
async def test_the_planner_survives_fuzzing(planning: str) -> None:
    agent = _agent()
    domain = parse_domain(agent.domain.read_text(encoding="utf-8"), str(agent.domain))
    planner_settings = PlannerSettings(agent=A, agent_file=AGENT_FILE, planning=planning)
    shell = TogetherService(
        f"{A}/planner", planner_settings, planner_main(planner_settings, domain, agent)
    )

    async def check(bus: Any) -> None:
        pass  # alive, no handler crashed: a fuzzed Tick may have put it in lockstep, where
        # a request waits for the world's next epoch (which no world sends here)

    await fuzz(shell, check)


async def test_the_scheduler_survives_fuzzing() -> None:
    scheduler_settings = SchedulerSettings(agent=A, agent_file=AGENT_FILE, load_map=False)
    mind = Mind(load_agent(AGENT_FILE, A))
    shell = TogetherService(
        f"{A}/scheduler", scheduler_settings, scheduler_main(mind, scheduler_settings)
    )

    async def check(bus: Any) -> None:
        key = keys.component_rpc(A, "scheduler", "state")
        reply = await bus.request(key, encode(StateRequest()))
        assert isinstance(decode_any(reply, (AgentState, ErrorReply)), AgentState)

    await fuzz(shell, check)


async def test_the_executor_survives_fuzzing() -> None:
    executor_settings = ExecutorSettings(agent=A)
    shell = TogetherService(f"{A}/executor", executor_settings, executor_main(executor_settings))

    async def check(bus: Any) -> None:
        pass  # alive and no handler crashed (checked by `fuzz` and `alone`)

    await fuzz(shell, check)


async def test_the_monitor_survives_fuzzing_and_its_recording_reads(tmp_path: Any) -> None:
    from cbdi_monitor.reader import read_messages
    from cbdi_monitor.service import MonitorSettings, monitor_main

    output = tmp_path / "fuzz.mcap"
    monitor_settings = MonitorSettings(output=str(output))
    shell = TogetherService("monitor", monitor_settings, monitor_main(monitor_settings))
    async with alone(shell) as (bus, ctx):
        for i, payload in enumerate(payloads()):
            await bus.publish(STREAMS[i % len(STREAMS)], payload)
            if i % 50 == 0:
                await asyncio.sleep(0.01)
        await asyncio.sleep(0.5)
        assert ctx.counters["handler_crash"] == 0
    recorded = list(read_messages(output))  # finished at stop: every file part reads
    assert len(recorded) >= len(payloads()) // 2, len(recorded)
