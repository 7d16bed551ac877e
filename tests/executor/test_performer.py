"""Action performers (`cbdi.performer`): a step whose action a performer carries out
goes to it, not to the world, and its outcome ends the step (on the in-memory bus)."""

from __future__ import annotations

import asyncio

from cbdi import keys
from cbdi.beliefs import BeliefSet, fact, to_wire
from cbdi.bus import LogSink, MemoryNetwork, messages
from cbdi.performer import ActionCall, Outcome, performer_key, serve_performer
from cbdi.runtime.together import Together, TogetherService
from cbdi.wire import decode, encode
from cbdi.wire.agent import ActionStatus, PartialPlan, PlanStep
from cbdi.wire.common import ErrorReply
from cbdi.wire.world import ActionReply, ActionRequest
from cbdi_executor.service import ExecutorSettings, executor_main

BELIEFS = BeliefSet.of([fact("docked", "robot1", "d1")])


class Dock:
    """Docks at once; the second call fails the way user code fails: it raises."""

    def __init__(self) -> None:
        self.calls: list[ActionCall] = []

    async def perform(self, call: ActionCall) -> Outcome:
        self.calls.append(call)
        if len(self.calls) > 1:
            raise RuntimeError("dock d2 is busy")
        await asyncio.sleep(0.01)
        return Outcome.success()


def charge(i: int, dock: str) -> PlanStep:
    return PlanStep(
        step_id=f"s{i}", action="charge", args=["robot1", dock], start=float(i), duration=5.0
    )


async def test_a_performer_carries_out_its_action_and_reports_how_it_ended() -> None:
    network = MemoryNetwork()
    settings = ExecutorSettings(agent="robot1", performer=("charge",))
    together = Together(
        [TogetherService("robot1/executor", settings, executor_main(settings))],
        network,
        log_level="error",
    )
    task = asyncio.create_task(together.run())
    bus = network.bus()
    world: list[ActionRequest] = []

    async def act(_key: str, payload: bytes) -> bytes:  # the world: must see nothing
        world.append(decode(payload, ActionRequest))
        return encode(ActionReply(request_id=world[-1].request_id, accepted=False))

    dock = Dock()
    served = [
        asyncio.create_task(bus.serve(keys.world_act("*"), act)),
        asyncio.create_task(serve_performer(bus, "robot1", "charge", dock)),
    ]
    try:
        async with asyncio.timeout(10):
            while keys.alive("robot1/executor") not in network.tokens:
                await asyncio.sleep(0.01)
        statuses = messages(bus, keys.executor_status("robot1"), ActionStatus, LogSink())
        beliefs = keys.scheduler_beliefs("robot1")
        await bus.publish(beliefs, encode(to_wire(BELIEFS, "robot1", 0.0, 0)))
        plan = PartialPlan(
            agent="robot1", plan_id="p", baseline="", steps=[charge(0, "d1"), charge(1, "d2")]
        )
        await bus.publish(keys.scheduler_plans("robot1"), encode(plan))
        seen: list[tuple[str, str, str]] = []
        async with asyncio.timeout(10):
            while ("s0", "succeeded", "") not in seen:
                _, st = await anext(statuses)
                seen.append((st.step_id, st.status, st.reason))
            await bus.publish(beliefs, encode(to_wire(BELIEFS, "robot1", 1.0, 1)))
            while not any(s[:2] == ("s1", "failed") for s in seen):
                _, st = await anext(statuses)
                seen.append((st.step_id, st.status, st.reason))
        assert ("s0", "running", "") in seen
        assert ("s1", "failed", "RuntimeError: dock d2 is busy") in seen
        assert [(c.action, c.args, c.duration) for c in dock.calls] == [
            ("charge", ("robot1", "d1"), 5.0),
            ("charge", ("robot1", "d2"), 5.0),
        ]
        assert world == []  # nothing went to the world
        # A request for another agent or action is refused, and the performer goes on.
        other = ActionRequest(agent="robot2", action="charge", request_id="x", args=["robot2"])
        answer = await bus.request(performer_key("robot1", "charge"), encode(other))
        assert "for 'robot1'" in decode(answer, ErrorReply).message
        assert not served[1].done()
    finally:
        for t in served:
            t.cancel()
        together.stop()
        assert await task == {"robot1/executor": 0}
