"""The safe stop at the executor (`rpc/stop`), which needs no scheduler: nothing starts
until resumed, what runs ends, and performers stop what they carry out; `cbdi ctl stop`
stops an agent whose scheduler does not answer (on the in-memory bus)."""

from __future__ import annotations

import argparse
import asyncio

import pytest

from cbdi import ctl, keys
from cbdi.beliefs import BeliefSet, fact, to_wire
from cbdi.bus import LogSink, MemoryNetwork, messages, publish, request
from cbdi.performer import (
    ActionCall,
    Outcome,
    outcomes_key,
    performer_key,
    serve_performer,
    stop_key,
)
from cbdi.runtime.together import Together, TogetherService
from cbdi.wire import decode, encode
from cbdi.wire.agent import ExecutorState, ExecutorStop, PartialPlan, PlanStep
from cbdi.wire.world import ActionOutcome, ActionReply, ActionRequest
from cbdi_executor.service import ExecutorSettings, executor_main
from tests_support import settle

BELIEFS = BeliefSet.of([fact("free", f"c_{x}_0") for x in range(1, 4)])


def move(i: int) -> PlanStep:
    return PlanStep(
        step_id=f"s{i}",
        action="move",
        args=["robot1", f"c_{i}_0", f"c_{i + 1}_0"],
        start=float(i),
        duration=1.0,
    )


async def stop(bus: object, op: str) -> ExecutorState:
    key = keys.component_rpc("robot1", "executor", "stop")
    msg = ExecutorStop(from_agent="operator", op=op)  # type: ignore[arg-type]
    return await request(bus, key, msg, ExecutorState)  # type: ignore[arg-type]


async def test_a_stopped_executor_starts_nothing_until_resumed(
    capsys: pytest.CaptureFixture[str],
) -> None:
    network = MemoryNetwork()
    settings = ExecutorSettings(agent="robot1")
    together = Together(
        [TogetherService("robot1/executor", settings, executor_main(settings))],
        network,
        log_level="error",
    )
    task = asyncio.create_task(together.run())
    bus = network.bus()
    seen: list[ActionRequest] = []

    async def act(_key: str, payload: bytes) -> bytes:
        req = decode(payload, ActionRequest)
        seen.append(req)
        return encode(
            ActionReply(request_id=req.request_id, accepted=True, starts_at=0.0, ends_at=1.0)
        )

    server = asyncio.create_task(bus.serve(keys.world_act("*"), act))
    try:
        async with asyncio.timeout(10):
            while keys.alive("robot1/executor") not in network.tokens:
                await asyncio.sleep(0.01)
        beliefs = keys.scheduler_beliefs("robot1")
        await bus.publish(beliefs, encode(to_wire(BELIEFS, "robot1", 0.0, 0)))
        plan = PartialPlan(agent="robot1", plan_id="p", baseline="", steps=[move(0), move(1)])
        await bus.publish(keys.scheduler_plans("robot1"), encode(plan))
        async with asyncio.timeout(5):
            while not seen:
                await asyncio.sleep(0.01)
        # No scheduler answers: `cbdi ctl stop` stops the executor all the same.
        args = argparse.Namespace(
            agents=["robot1"],
            what="stop",
            sender="operator",
            group="operator",
            timeout=0.3,
            wait=5.0,
        )
        waiting = asyncio.create_task(ctl._stop(bus, args))
        async with asyncio.timeout(5):
            while not (await stop(bus, "state")).halted:
                await asyncio.sleep(0.01)
        assert (await stop(bus, "state")).running == "s0"  # the running move ends by itself
        done = ActionOutcome(
            agent="robot1",
            request_id=seen[0].request_id,
            action="move",
            status="succeeded",
            reason="",
            epoch=1,
            time=1.0,
        )
        await bus.publish(keys.world_outcomes("robot1"), encode(done))
        await bus.publish(beliefs, encode(to_wire(BELIEFS, "robot1", 1.0, 1)))
        assert await asyncio.wait_for(waiting, 5) == 0
        out = capsys.readouterr()
        assert "robot1 stopped at t=1" in out.out and "scheduler did not answer" in out.err
        await bus.publish(beliefs, encode(to_wire(BELIEFS, "robot1", 2.0, 2)))
        await asyncio.sleep(0.2)
        assert len(seen) == 1  # s1 is due, but nothing starts while stopped
        state = await stop(bus, "resume")
        assert not state.halted
        async with asyncio.timeout(5):
            while len(seen) < 2:
                await asyncio.sleep(0.01)
        assert seen[1].args[2] == "c_2_0"
    finally:
        server.cancel()
        together.stop()
        assert await task == {"robot1/executor": 0}


class Slow:
    async def perform(self, call: ActionCall) -> Outcome:
        await asyncio.Event().wait()  # until stopped
        return Outcome.success()


async def test_a_performer_stops_what_it_carries_out_at_a_safe_stop() -> None:
    bus = MemoryNetwork().bus()
    outcomes = messages(bus, outcomes_key("robot1"), ActionOutcome, LogSink())
    served = asyncio.create_task(serve_performer(bus, "robot1", "charge", Slow()))
    try:
        await settle()  # the performer serves
        call = ActionRequest(
            agent="robot1", action="charge", request_id="r1", args=["robot1"], duration=60
        )
        reply = decode(
            await bus.request(performer_key("robot1", "charge"), encode(call)), ActionReply
        )
        assert reply.accepted and reply.ends_at == 60.0
        await publish(bus, stop_key("robot1"), ExecutorStop(from_agent="op", op="stop"))
        async with asyncio.timeout(5):
            _, outcome = await anext(outcomes)
        assert (outcome.request_id, outcome.status) == ("r1", "failed")
        assert outcome.reason == "stopped by a safe stop"
    finally:
        served.cancel()
