"""Every service shell survives garbage and schema-valid nonsense (issue 15).

Each service runs alone on the in-memory bus (`cbdi.runtime.together`). The test sends it
undecodable bytes, messages of the wrong shape, and messages that are well-formed but
nonsense (an unknown check operator, an empty belief name, a step at `inf`); each is
reported on the service's error stream, naming the key (and the sender, when the message
says who it is), and the service still answers the valid message that follows.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
from collections.abc import AsyncIterator

import msgpack
import pytest
from cbdi_recycling.wire import Percepts
from test_online import CORRIDOR, beliefs

from cbdi import keys
from cbdi.agentfile import read_agent_file
from cbdi.beliefs import to_wire
from cbdi.bus import LogSink, MemoryNetwork, messages, request
from cbdi.bus.memory import MemoryBus
from cbdi.bus.typed import dropping
from cbdi.clock import ManualClock
from cbdi.errors import CbdiError, RejectedInputError, RequestFailedError
from cbdi.runtime import ServiceContext
from cbdi.runtime.together import Together, TogetherService
from cbdi.wire import decode, encode
from cbdi.wire.agent import ActionStatus, BeliefsUpdate, Check, PartialPlan, PlanStep
from cbdi.wire.common import ErrorReply, ErrorReport
from cbdi.wire.fields import MAX_ITEMS
from cbdi.wire.planner import SearchRequest, SearchStatus
from cbdi.wire.world import (
    ActionReply,
    ActionRequest,
    EpochAck,
    ItemView,
    StatsRequest,
    WorldStats,
)
from cbdi_executor.service import ExecutorSettings, executor_main
from cbdi_planner.agent.service import PlannerSettings, planner_main
from cbdi_planner.pddl import parse_domain
from cbdi_scheduler.agentfile import load_agent
from cbdi_scheduler.mind import Mind
from cbdi_scheduler.service import SchedulerSettings, scheduler_main
from cbdi_world.service import WorldSettings, build_world, world_main
from tests_support import REPO

MAP = str(REPO / "domains/recycling/maps/paper-7x7.toml")
AGENT_FILE = str(REPO / "domains/recycling/agents/recycler.toml")

GARBAGE = [
    b"",
    b"\xc1\xc1\xc1",
    b"not msgpack",
    msgpack.packb([1, 2, 3]),
    msgpack.packb({"schema": "cbdi.recycling.Percepts/1", "agent": 5}),
    msgpack.packb({"schema": "cbdi.nothing.Such/1", "agent": "robot1"}),
]


def raw(message: object, **fields: object) -> bytes:
    """`message` encoded with some fields replaced by values its type forbids."""
    data = msgpack.unpackb(encode(message))  # type: ignore[arg-type]
    data.update(fields)
    return msgpack.packb(data)  # type: ignore[no-any-return]


def percepts(**kw: object) -> Percepts:
    fields: dict[str, object] = {
        "agent": "robot1",
        "epoch": 0,
        "time": 0.0,
        "position": (1, 1),
        "depth": 1,
        "free": [(1, 2)],
        "blocked": [],
        "items": [],
        "holding": [],
    }
    return Percepts(**{**fields, **kw})  # type: ignore[arg-type]


def step(**kw: object) -> PlanStep:
    fields: dict[str, object] = {
        "step_id": "s1",
        "action": "move",
        "args": ["robot1", "c_1_1", "c_1_2"],
        "start": 0.0,
        "duration": 1.0,
        "at_start": [Check(atom=["in", "robot1", "c_9_9"])],  # does not hold: refused
    }
    return PlanStep(**{**fields, **kw})  # type: ignore[arg-type]


@contextlib.asynccontextmanager
async def alone(service: TogetherService) -> AsyncIterator[tuple[MemoryBus, ServiceContext]]:
    """Run `service` on its own network until the block ends; yield a bus and its context."""
    network = MemoryNetwork()
    together = Together([service], network, log_level="error")
    task = asyncio.create_task(together.run())
    async with asyncio.timeout(10):
        while keys.alive(service.service) not in network.tokens:
            await asyncio.sleep(0.01)
    try:
        yield network.bus(), together.contexts[0]
    finally:
        assert not task.done(), "the service ended"
        together.stop()
        codes = await task
        assert codes == {service.service: 0}


async def flood(bus: MemoryBus, key: str, payloads: list[bytes]) -> None:
    for payload in payloads:
        await bus.publish(key, payload)
    await asyncio.sleep(0.05)  # the service's loop takes them in


def bad_inputs(ctx: ServiceContext) -> int:
    return sum(n for k, n in ctx.counters.items() if k.startswith("bad_input"))


async def test_the_executor_rejects_an_unknown_check_operator_and_runs_the_next_plan() -> None:
    settings = ExecutorSettings(agent="robot1")
    async with alone(TogetherService("robot1/executor", settings, executor_main(settings))) as (
        bus,
        ctx,
    ):
        errors = messages(bus, keys.errors("robot1/executor"), ErrorReport, LogSink())
        statuses = messages(bus, keys.executor_status("robot1"), ActionStatus, LogSink())
        valid = PartialPlan(agent="robot1", plan_id="p1", baseline="", steps=[step()])
        move_op = raw(valid, steps=[raw_step(op="move")])
        nonsense = [
            move_op,
            raw(valid, steps=[raw_step(start=math.inf)]),
            raw(valid, steps=[raw_step(value=math.nan, op="LT")]),
            raw(valid, agent=""),
            raw(valid, steps=[{**raw_step(), "at_start": [raw_step()["at_start"][0]] * 1001}]),
        ]
        key = keys.scheduler_plans("robot1")
        await flood(bus, key, [*GARBAGE, *nonsense])
        await flood(bus, keys.scheduler_beliefs("robot1"), GARBAGE)
        update = to_wire(beliefs(), "robot1", 0.0, 0)
        await bus.publish(keys.scheduler_beliefs("robot1"), encode(update))
        await bus.publish(key, encode(valid))
        async with asyncio.timeout(5):
            _, status = await anext(statuses)
            while status.status != "refused":
                _, status = await anext(statuses)
        assert status.step_id == "s1"
        assert bad_inputs(ctx) == 2 * len(GARBAGE) + len(nonsense)
        async with asyncio.timeout(5):
            reports = [(await anext(errors))[1] for _ in range(len(GARBAGE) + 1)]
        operator = reports[len(GARBAGE)]
        assert operator.key == key and "from robot1" in operator.message
        assert "'move'" in operator.message and "$.steps[0].at_start[0].op" in operator.message


def raw_step(**fields: object) -> dict[str, object]:
    """A plan step as a msgpack map, its check's fields replaced by `fields`."""
    check_fields = {k: v for k, v in fields.items() if k in ("op", "value")}
    step_fields = {k: v for k, v in fields.items() if k not in check_fields}
    data = msgpack.unpackb(encode(step()))
    data["at_start"][0].update(check_fields)
    data.update(step_fields)
    return data  # type: ignore[no-any-return]


async def test_the_scheduler_rejects_an_empty_belief_name_and_revises_on_the_next_percepts() -> (
    None
):
    settings = SchedulerSettings(agent="robot1", agent_file=AGENT_FILE, load_map=False)
    mind = Mind(load_agent(AGENT_FILE, "robot1"))
    shell = TogetherService("robot1/scheduler", settings, scheduler_main(mind, settings))
    async with alone(shell) as (bus, ctx):
        errors = messages(bus, keys.errors("robot1/scheduler"), ErrorReport, LogSink())
        updates = messages(bus, keys.scheduler_beliefs("robot1"), BeliefsUpdate, LogSink())
        valid = percepts(holding=["p1"])
        nonsense = [
            raw(valid, holding=[""]),
            raw(valid, holding=["p1"] * (MAX_ITEMS + 1)),
            raw(valid, time=math.nan),
            raw(valid, items=[{"schema": "cbdi.world.ItemView/1", "name": "", "cell": [1, 1]}]),
            raw(valid, position=[1]),
            raw(valid, agent="no/such agent"),
        ]
        key = keys.world_percepts("robot1")
        await flood(bus, key, [*GARBAGE, *nonsense])
        await flood(bus, keys.planner_plans("robot1"), GARBAGE)
        await flood(bus, keys.executor_status("robot1"), [raw(status(), status="dancing")])
        await bus.publish(key, encode(valid))
        async with asyncio.timeout(5):
            _, update = await anext(updates)
        assert ["holding", "robot1", "p1"] in update.facts
        assert bad_inputs(ctx) == 2 * len(GARBAGE) + len(nonsense) + 1
        async with asyncio.timeout(5):
            reports = [(await anext(errors))[1] for _ in range(len(GARBAGE) + 1)]
        empty = reports[len(GARBAGE)]
        assert empty.key == key and "from robot1" in empty.message
        assert "$.holding[0]" in empty.message


def status() -> ActionStatus:
    return ActionStatus(
        agent="robot1",
        plan_id="p1",
        step_id="s1",
        action="move",
        status="running",
        reason="",
        time=0.0,
    )


async def test_the_planner_refuses_nonsense_requests_and_serves_the_next_one() -> None:
    settings = PlannerSettings(agent="robot1", agent_file=AGENT_FILE)
    agent = read_agent_file(AGENT_FILE, "robot1")
    domain = parse_domain(agent.domain.read_text(encoding="utf-8"), str(agent.domain))
    shell = TogetherService("robot1/planner", settings, planner_main(settings, domain, agent))
    async with alone(shell) as (bus, ctx):
        statuses = messages(bus, keys.planner_status("robot1"), SearchStatus, LogSink())
        valid = SearchRequest(agent="robot1", request_id="s1", kind="start", problem=CORRIDOR)
        deep = "(define (problem p) (:domain recycling) (:goal " + "(and " * 500 + ")" * 502
        nonsense = [
            raw(valid, kind="move"),
            raw(valid, goal=[[]]),
            raw(valid, goal=[[""]]),
            raw(valid, request_id=""),
            encode(SearchRequest(agent="robot1", request_id="s2", kind="start", problem=deep)),
            encode(SearchRequest(agent="robot1", request_id="s3", kind="start", goal=[["x"]])),
        ]
        key = keys.planner_requests("robot1")
        await flood(bus, key, [*GARBAGE, *nonsense])
        await flood(
            bus,
            keys.scheduler_beliefs("robot1"),
            [raw(to_wire(beliefs(), "robot1", 0.0, 0), fluents=[[["f"], math.inf]])],
        )
        await bus.publish(key, encode(valid))
        async with asyncio.timeout(10):
            _, answer = await anext(statuses)
            while answer.request_id != "s1":  # nothing answers the refused requests
                _, answer = await anext(statuses)
        assert answer.status == "searching"
        assert bad_inputs(ctx) == len(GARBAGE) + len(nonsense) + 1
        assert ctx.counters["handler_crash"] == 0  # the deep problem is a parse error


async def test_the_world_answers_nonsense_requests_with_errors_and_serves_the_next_one() -> None:
    settings = WorldSettings(map=MAP, simulator="recycling", agent=("robot1",), wait_agents=0)
    shell = TogetherService("world", settings, world_main(build_world(settings), ManualClock()))
    async with alone(shell) as (bus, ctx):
        act = keys.world_rpc("act")
        valid = ActionRequest(agent="robot1", action="move", request_id="r1", target=(1, 2))
        nonsense = [
            raw(valid, agent=""),
            raw(valid, target=[1]),
            raw(valid, target=[2**40, 1]),
            raw(valid, request_id="x" * 1000),
        ]
        for payload in [*GARBAGE, *nonsense]:
            reply = decode(await bus.request(act, payload), ErrorReply)
            assert reply.code == "bad_message", payload
        odd = ActionRequest(agent="robot1", action="fly", request_id="r0", target=(1, 2))
        refused = await request(bus, act, odd, ActionReply)
        assert not refused.accepted and refused.reason
        # An action of robot1 asked on another agent's key: refused, not performed.
        with pytest.raises(RequestFailedError) as posing:
            await request(bus, keys.world_act("robot2"), valid, ActionReply)
        assert posing.value.code == "not_own_agent" and ctx.counters["act_not_own"] == 1
        own = await request(bus, keys.world_act("robot1"), valid, ActionReply)
        assert own.request_id == "r1"  # served (the simulator's answer, not a refusal)
        ack = EpochAck(agent="robot1", epoch=0)
        await flood(
            bus, keys.agent_ack("robot1"), [*GARBAGE, raw(ack, epoch=-7), raw(ack, stage="x")]
        )
        stats = await request(bus, keys.world_rpc("stats"), StatsRequest(), WorldStats)
        assert [a.agent for a in stats.agents] == ["robot1"]
        assert bad_inputs(ctx) == 2 * len(GARBAGE) + len(nonsense) + 2


class Boom(CbdiError):
    pass


def test_dropping_reports_a_domain_error_with_schema_sender_and_key_and_goes_on() -> None:
    sink = LogSink()
    message = percepts(items=[ItemView(name="p1", cell=(1, 1))])
    for error in (ValueError("a belief needs a name"), Boom("no such thing")):
        with dropping(sink, "cbdi/world/percepts/robot1", message):
            raise error
    with dropping(sink, "cbdi/world/percepts/robot1", message):
        raise KeyError("a bug")
    (k1, e1), (_, e2), (_, e3) = sink.errors
    assert isinstance(e1, RejectedInputError) and isinstance(e2, RejectedInputError)
    assert k1 == "cbdi/world/percepts/robot1" and e1.sender == "robot1"
    assert str(e1) == (
        "rejected cbdi.recycling.Percepts/1 message from robot1 on cbdi/world/percepts/robot1:"
        " a belief needs a name"
    )
    assert isinstance(e3, KeyError)  # a bug is a crash, reported as such
    with pytest.raises(asyncio.CancelledError), dropping(sink, "k", message):
        raise asyncio.CancelledError  # cancellation is never swallowed
