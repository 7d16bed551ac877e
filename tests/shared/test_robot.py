"""A robot's own process in lockstep (`cbdi.robot.Robot`), on the in-memory bus: the
world's ticks drive its performers' `call.sleep`, their outcomes carry the epoch they
ended in and come before the epoch's ack, which counts them; the calls the executor
starts in an epoch run to their first wait before the epoch is done; its sensors read
once per period of simulated time and stamp what they tell with the epoch."""

from __future__ import annotations

import asyncio

import pytest

from cbdi import keys
from cbdi.bus import LogSink, MemoryNetwork, messages, publish, request, serve
from cbdi.performer import ActionCall, Outcome, outcomes_key, performer_key
from cbdi.robot import Robot, SimSleeper
from cbdi.sensor import Prototype
from cbdi.wire.agent import AgentReply, AgentRequest
from cbdi.wire.world import (
    ActionOutcome,
    ActionReply,
    ActionRequest,
    EpochAck,
    Tick,
    WorldInfo,
    WorldInfoRequest,
)

MEMBER = "robot1/performer"


class Walk:
    """Walks for the planned time, in two halves; fails a walk to nowhere at once."""

    def __init__(self) -> None:
        self.halfway: list[float] = []
        self.asked: list[str] = []  # what it asked before its first wait (a body: the world)

    async def perform(self, call: ActionCall) -> Outcome:
        if call.args[-1] == "nowhere":
            return Outcome.failure("no such place")
        for _ in range(3):  # something that takes a few turns of the loop, not a sleep
            await asyncio.sleep(0)
        self.asked.append(call.args[-1])
        await call.sleep(call.duration / 2)
        self.halfway.append(call.duration)
        await call.sleep(call.duration / 2)
        return Outcome.success()


class Door:
    prototype = Prototype("door_open", 1)

    def __init__(self) -> None:
        self.reads = 0

    async def read(self) -> list[tuple[str, ...]]:
        self.reads += 1
        return [("d1",)] if self.reads % 2 else []


async def test_a_performer_in_lockstep_ends_at_the_epoch_its_sleeps_end() -> None:
    net = MemoryNetwork()
    info = WorldInfo(
        map_name="m", agents=["robot1"], epoch_duration=1.0, durations={},
        members=["robot1/executor", MEMBER], lockstep=True,
    )  # fmt: skip
    told: list[AgentRequest] = []

    async def answer_info(_key: str, _req: WorldInfoRequest) -> WorldInfo:
        return info

    async def answer_agent(_key: str, req: AgentRequest) -> AgentReply:
        told.append(req)
        return AgentReply(accepted=True)

    sink = LogSink()
    told_key = keys.agent_request("robot1", "sensors")
    helpers = [
        asyncio.create_task(
            serve(net.bus(), keys.world_rpc("info"), WorldInfoRequest, answer_info, sink)
        ),
        asyncio.create_task(serve(net.bus(), told_key, AgentRequest, answer_agent, sink)),
    ]
    heard = net.bus()
    acks = messages(heard, keys.epoch_ack("robot1", "performer"), EpochAck, sink)
    outcomes = messages(heard, outcomes_key("robot1"), ActionOutcome, sink)
    walk, door = Walk(), Door()
    robot = Robot(net.bus(), "robot1")
    robot.perform("walk", walk)
    robot.sense(door, rate=0.5)  # every 2 simulated seconds
    running = asyncio.create_task(robot.run())
    world = net.bus()
    try:
        async with asyncio.timeout(10):
            ready = (await anext(acks))[1]
            assert (ready.epoch, ready.stage) == (-1, "ready")  # the start barrier
            executor = net.bus()
            ended: list[ActionOutcome] = []
            for epoch in range(6):
                tick = Tick(
                    epoch=epoch, time=float(epoch), epoch_duration=1.0, speed=0.0, lockstep=True
                )
                await publish(world, keys.world_stream("clock"), tick, block=True)
                for stage in ("beliefs", "done"):
                    ack = (await anext(acks))[1]
                    assert (ack.epoch, ack.stage) == (epoch, stage)
                    counted = ack.sent.get(outcomes_key("robot1"), 0)
                    while len(ended) < counted:  # what the ack counts has come
                        ended.append((await anext(outcomes))[1])
                    if stage == "done":
                        break
                    if epoch == 0:  # the executor's dispatch of epoch 0: a 3 s walk, a bad one
                        for rid, where in (("w1", "kitchen"), ("w2", "nowhere")):
                            req = ActionRequest(
                                agent="robot1", action="walk", request_id=rid,
                                args=["robot1", where], duration=3.0,
                            )  # fmt: skip
                            key = performer_key("robot1", "walk")
                            reply = await request(executor, key, req, ActionReply)
                            assert reply.accepted
                            assert (reply.starts_at, reply.ends_at) == (0.0, 3.0)
                    done = EpochAck(agent="robot1", epoch=epoch, component="executor")
                    await publish(executor, keys.epoch_ack("robot1", "executor"), done, block=True)
                # The walk ran to its first wait before the epoch was done (what it asks
                # there, the world serves in this epoch).
                assert walk.asked == ["kitchen"]
    finally:
        running.cancel()
        for h in helpers:
            h.cancel()
    # The bad walk failed at once: counted in epoch 0's done ack, stamped 0 (its start).
    # The walk slept 1.5 + 1.5 simulated seconds: woken at epochs 2 and 3, it ended at 3.
    assert [(o.request_id, o.status, o.epoch) for o in ended] == [
        ("w2", "failed", 0),
        ("w1", "succeeded", 3),
    ]
    assert walk.halfway == [3.0]
    # The sensor read at 0, 2 and 4 s; what changed carries the epoch it was read in.
    assert door.reads == 3
    assert [(r.op, r.belief, r.epoch) for r in told] == [
        ("add_belief", "(door_open d1)", 0),
        ("del_belief", "(door_open d1)", 2),
        ("add_belief", "(door_open d1)", 4),
    ]


async def test_a_sim_sleep_ends_at_the_first_time_at_or_past_its_end() -> None:
    clock = SimSleeper()
    woke: list[str] = []

    async def nap(name: str, seconds: float) -> None:
        await clock.sleep(seconds)
        woke.append(name)

    tasks = [asyncio.create_task(nap(n, s)) for n, s in (("b", 2.0), ("a", 1.5), ("c", 0.0))]
    for _ in range(3):
        await asyncio.sleep(0)
    assert len(clock.parked) == 2 and woke == ["c"]  # a sleep of 0 waits for no tick
    clock.advance(1.0)
    await asyncio.sleep(0)
    assert woke == ["c"]
    clock.advance(2.0)  # both due: in the order they end
    await asyncio.gather(*tasks)
    assert woke == ["c", "a", "b"] and not clock.parked
    # A loop of short sleeps catches up with the run's time at once, then waits.
    steps: list[float] = []

    async def control() -> None:
        for _ in range(30):
            await clock.sleep(0.1)
            steps.append(clock.now)

    loop = asyncio.create_task(control())
    for _ in range(5):
        await asyncio.sleep(0)
    assert steps == [] and loop in clock.parked  # 2.1 is past the run's time (2.0)
    clock.advance(3.0)
    for _ in range(15):
        await asyncio.sleep(0)
    assert len(steps) == 10 and loop in clock.parked  # 2.1 .. 3.0, then 3.1 waits
    loop.cancel()
    with pytest.raises(ValueError, match="nan"):
        await clock.sleep(float("nan"))
