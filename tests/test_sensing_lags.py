"""A robot whose sensing lags its performer (issue 31), every service in one process on
the in-memory bus, in real time: the clock world, the rover's planner, scheduler and
executor, its `move` performer and its `at` sensor.

The rover drives a -> b -> c. While it drives the sensor sees it nowhere; `move a b`'s
outcome reaches the executor before the sensor sees it at b. So `move b c` is due while
`(at robot1 b)` is not believed: refused at once (condition_wait 0), and the replan from
beliefs with the rover nowhere fails. The desire says it waits and why; the sensor's
reading of b, a belief change from a sensor, retries the search, and the rover gets to
c. With a condition wait, the step waits for the reading instead and nothing fails.
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from cbdi import keys
from cbdi.agentfile import read_agent_file
from cbdi.bus import LogSink, MemoryNetwork, messages, request
from cbdi.performer import ActionCall, Outcome, serve_performer
from cbdi.runtime.together import Together, TogetherService
from cbdi.sensor import Prototype, run_sensor
from cbdi.wire.agent import ActionStatus, AgentReply, AgentRequest, DesireEvent
from cbdi_executor.service import ExecutorSettings, executor_main
from cbdi_planner.agent.service import PlannerSettings, planner_main
from cbdi_planner.pddl import parse_domain
from cbdi_scheduler.agentfile import load_agent
from cbdi_scheduler.mind import Mind
from cbdi_scheduler.service import SchedulerSettings, scheduler_main
from cbdi_world.service import WorldSettings, build_world, world_main

ROVER = str(Path(__file__).resolve().parent / "scheduler/rover/agent.toml")
SPEED = 2.0  # simulated s per wall s


@dataclass
class Rover:
    """Where the rover is, and where its sensor says it is (`lag`: only when told)."""

    where: str = "a"
    seen: str | None = "a"
    lag: bool = True
    moves: list[tuple[str, str]] = field(default_factory=list)


class Move:
    """Performs (move ?r ?from ?to): the rover leaves at once and arrives at the end."""

    def __init__(self, rover: Rover) -> None:
        self.rover = rover

    async def perform(self, call: ActionCall) -> Outcome:
        _robot, here, there = call.args
        if self.rover.where != here:
            return Outcome.failure(f"not at {here}")
        self.rover.moves.append((here, there))
        self.rover.where, self.rover.seen = "", None  # on its way: seen nowhere
        await asyncio.sleep(call.duration / SPEED)
        self.rover.where = there
        if not self.rover.lag:
            self.rover.seen = there
        return Outcome.success()


class Place:
    """Senses (at ?r ?p) as the (lagging) sensor sees it."""

    prototype = Prototype("at", 2)

    def __init__(self, rover: Rover) -> None:
        self.rover = rover

    async def read(self) -> list[tuple[str, ...]]:
        return [("robot1", self.rover.seen)] if self.rover.seen else []


def services(condition_wait: float) -> list[TogetherService]:
    raw = read_agent_file(ROVER, "robot1")
    domain = parse_domain(raw.domain.read_text(encoding="utf-8"), str(raw.domain))
    world = WorldSettings(
        simulator="clock", agent=("robot1",), speed=SPEED, option=("epoch_duration=0.5",)
    )
    planner = PlannerSettings(agent="robot1", agent_file=ROVER)
    scheduler = SchedulerSettings(agent="robot1", agent_file=ROVER)
    executor = ExecutorSettings(agent="robot1", performer=("move",), condition_wait=condition_wait)
    mind = Mind(load_agent(ROVER, "robot1"))
    return [
        TogetherService("world", world, world_main(build_world(world))),
        TogetherService("robot1/planner", planner, planner_main(planner, domain, raw)),
        TogetherService("robot1/scheduler", scheduler, scheduler_main(mind, scheduler)),
        TogetherService("robot1/executor", executor, executor_main(executor)),
    ]


@pytest.mark.parametrize("condition_wait", [0.0, 4.0], ids=["refused", "waits"])
async def test_a_step_before_its_sensor_reading_is_refused_then_retried_or_waits(
    condition_wait: float,
) -> None:
    network = MemoryNetwork()
    together = Together(services(condition_wait), network, log_level="error")
    task = asyncio.create_task(together.run())
    bus = network.bus()
    rover = Rover()
    robot: list[asyncio.Task[None]] = []
    desires = messages(bus, keys.scheduler_desires("robot1"), DesireEvent, LogSink())
    statuses = messages(bus, keys.executor_status("robot1"), ActionStatus, LogSink())
    seen: list[tuple[str, str, str]] = []  # desire events: (desire, event, reason)
    steps: list[tuple[str, str, str]] = []  # step statuses: (action args, status, reason)

    async def follow_steps() -> None:
        async for _, st in statuses:
            steps.append((st.step_id, st.status, st.reason))
            if st.status == "waiting" and st.reason and rover.lag:  # sensing catches up
                rover.lag, rover.seen = False, rover.where

    async def until(event: str) -> DesireEvent:
        while True:
            _, e = await anext(desires)
            seen.append((e.desire, e.event, e.reason))
            if e.event in (event, "dropped"):
                return e

    follower = asyncio.create_task(follow_steps())
    try:
        async with asyncio.timeout(60):
            while keys.alive("robot1/scheduler") not in network.tokens:
                await asyncio.sleep(0.02)
            robot += [
                asyncio.create_task(serve_performer(bus, "robot1", "move", Move(rover))),
                asyncio.create_task(run_sensor(bus, "robot1", Place(rover), rate=20.0)),
            ]
            go = AgentRequest(
                from_agent="op",
                group="operator",
                op="add_desire",
                desire="go",
                goal=["(at robot1 c)"],
                deadline=120,
            )
            rpc = keys.agent_request("robot1", "operator")
            while not (await request(bus, rpc, go, AgentReply)).accepted:
                await asyncio.sleep(0.1)  # the scheduler may not serve yet
            if condition_wait == 0:
                waiting = await until("waiting")
                assert waiting.event == "waiting", seen
                assert "searching again when the beliefs change" in waiting.reason, seen
                while not any(s[1] == "refused" and "(at robot1 b)" in s[2] for s in steps):
                    await asyncio.sleep(0.02)  # its status comes on another key
                assert rover.where == "b" and rover.seen is None  # the reading is late
                rover.lag, rover.seen = False, "b"  # the sensor catches up: retried
            achieved = await until("achieved")
        assert achieved.event == "achieved", seen
        assert rover.where == "c" and rover.moves == [("a", "b"), ("b", "c")]
        if condition_wait:
            assert ("waiting", "at start condition (at robot1 b) does not hold") in [
                s[1:] for s in steps
            ], steps
            assert not any(s[1] in ("refused", "failed") for s in steps), steps
            assert not any(e[1] == "waiting" for e in seen), seen
    finally:
        follower.cancel()
        for t in robot:
            t.cancel()
        together.stop()
        await asyncio.gather(task, follower, *robot, return_exceptions=True)
