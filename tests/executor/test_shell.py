"""The executor's service shell on the in-memory bus: what its core decides is sent.

A step the world rejects while an early arrest waits ends the arrest: the report goes out
(it was dropped: `send` kept only the statuses of the world's answer) and names the last
step that ran, not a cancelled one.
"""

from __future__ import annotations

import asyncio

from cbdi import keys
from cbdi.beliefs import BeliefSet, fact, to_wire
from cbdi.bus import LogSink, MemoryNetwork, messages
from cbdi.runtime.together import Together, TogetherService
from cbdi.wire import decode, encode
from cbdi.wire.agent import ArrestReport, EarlyArrest, PartialPlan, PlanStep
from cbdi.wire.world import ActionOutcome, ActionReply, ActionRequest
from cbdi_executor.service import ExecutorSettings, executor_main

BELIEFS = BeliefSet.of(
    [fact("in", "robot1", "c_0_0")] + [fact("free", f"c_{x}_0") for x in range(1, 4)]
)


def move(i: int) -> PlanStep:
    return PlanStep(
        step_id=f"s{i}",
        action="move",
        args=["robot1", f"c_{i}_0", f"c_{i + 1}_0"],
        start=float(i),
        duration=1.0,
    )


async def test_a_rejection_during_an_early_arrest_sends_a_true_arrest_report() -> None:
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
        if len(seen) == 1:
            return encode(
                ActionReply(request_id=req.request_id, accepted=True, starts_at=0.0, ends_at=1.0)
            )
        return encode(ActionReply(request_id=req.request_id, accepted=False, reason="busy"))

    server = asyncio.create_task(bus.serve(keys.world_act("*"), act))
    try:
        async with asyncio.timeout(10):
            while keys.alive("robot1/executor") not in network.tokens:
                await asyncio.sleep(0.01)
        reports = messages(bus, keys.executor_arrested("robot1"), ArrestReport, LogSink())
        beliefs = keys.scheduler_beliefs("robot1")
        await bus.publish(beliefs, encode(to_wire(BELIEFS, "robot1", 0.0, 0)))
        plan = PartialPlan(
            agent="robot1", plan_id="p", baseline="", steps=[move(0), move(1), move(2)]
        )
        await bus.publish(keys.scheduler_plans("robot1"), encode(plan))
        async with asyncio.timeout(5):
            while not seen:
                await asyncio.sleep(0.01)
        arrest = EarlyArrest(agent="robot1", plan_id="p", after_step="s1")
        await bus.publish(keys.scheduler_arrest("robot1"), encode(arrest))
        await asyncio.sleep(0.05)
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
        moved = BELIEFS.removing([fact("in", "robot1", "c_0_0")]).adding(
            [fact("in", "robot1", "c_1_0")]
        )
        await bus.publish(beliefs, encode(to_wire(moved, "robot1", 1.0, 1)))
        async with asyncio.timeout(5):
            _, report = await anext(reports)
        assert len(seen) == 2 and seen[1].args[2] == "c_2_0"  # s1 went out and was rejected
        assert report.plan_id == "p" and report.last_step == "s0"
        assert report.cancelled == ["s2"]
    finally:
        server.cancel()
        together.stop()
        assert await task == {"robot1/executor": 0}
