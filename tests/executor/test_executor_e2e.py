"""The executor as a real process over Zenoh: it runs a plan in the real world, checks
conditions against the beliefs it is sent, reports every step, stops on an early arrest.
The test plays the scheduler, a lockstep member: it turns percepts into beliefs, sends
the plan, and acknowledges each epoch with what it sent (`cbdi.lockstep`).
"""

from __future__ import annotations

import asyncio

import pytest
from cbdi_recycling.events import revise_from_percepts
from cbdi_recycling.wire import Percepts

from cbdi import keys
from cbdi.beliefs import BeliefSet, to_wire
from cbdi.bus import BusConfig, LogSink, messages, open_bus, publish, request
from cbdi.bus.base import Bus
from cbdi.lockstep import announce_ready, send_ack
from cbdi.wire.agent import ActionStatus, ArrestReport, Check, EarlyArrest, PartialPlan, PlanStep
from cbdi.wire.world import (
    StatsRequest,
    WorldStats,
)
from tests_support import REPO, wait_for

pytestmark = pytest.mark.e2e
CORRIDOR = str(REPO / "domains/recycling/maps/corridor-6x3.toml")


def move(i: int, x: int, to: int, start: float) -> PlanStep:
    return PlanStep(
        step_id=f"s{i}",
        action="move",
        args=["robot1", f"c_{x}_1", f"c_{to}_1"],
        start=start,
        duration=1.0,
        at_start=[Check(atom=["in", "robot1", f"c_{x}_1"])],
        over_all=[Check(atom=["free", f"c_{to}_1"])],
    )


def corridor_plan(pickup_cell: str = "c_4_1") -> PartialPlan:
    steps = [
        move(1, 1, 2, 0),
        move(2, 2, 3, 1),
        move(3, 3, 4, 2),
        PlanStep(
            step_id="s4",
            action="litter_pickup",
            args=["robot1", "plastic_4_1", "c_4_1"],
            start=3,
            duration=3,
            at_start=[
                Check(atom=["litter_pose", "plastic_4_1", pickup_cell]),
                Check(atom=["loaded_amount", "robot1"], op="LT", value=3),
            ],
        ),
        move(5, 4, 3, 6),
        move(6, 3, 2, 7),
        move(7, 2, 1, 8),
        PlanStep(
            step_id="s8",
            action="recycle",
            args=["robot1", "plastic_4_1", "bin", "c_1_1", "c_0_1"],
            start=9,
            duration=3,
            at_start=[Check(atom=["holding", "robot1", "plastic_4_1"])],
        ),
    ]
    return PartialPlan(agent="robot1", plan_id="p1", baseline="", steps=steps, complete=True)


async def play_scheduler(
    bus: Bus, plan: PartialPlan, arrest_after: str = "", until: str = "s8", settle: float = 0.0
) -> tuple[list[ActionStatus], ArrestReport | None]:
    """Send beliefs every epoch and the plan once; collect statuses until `until` ends."""
    sink = LogSink()
    percepts = messages(bus, keys.world_percepts("robot1"), Percepts, sink)
    statuses = messages(bus, keys.executor_status("robot1"), ActionStatus, sink)
    arrests = messages(bus, keys.executor_arrested("robot1"), ArrestReport, sink)
    seen: list[ActionStatus] = []
    report: ArrestReport | None = None
    beliefs = BeliefSet()

    async def feed() -> None:
        nonlocal beliefs
        sent = False
        async for _, p in percepts:
            beliefs = revise_from_percepts(beliefs, p)
            await publish(
                bus,
                keys.scheduler_beliefs("robot1"),
                to_wire(beliefs, "robot1", p.time, p.epoch),
                block=True,
            )
            if not sent:
                await publish(bus, keys.scheduler_plans("robot1"), plan, block=True)
                sent = True
            await send_ack(bus, "robot1", "scheduler", p.epoch, "beliefs")
            await send_ack(bus, "robot1", "scheduler", p.epoch, "done")

    async def watch_arrest() -> None:
        nonlocal report
        _, report = await anext(arrests)

    feeder = asyncio.create_task(feed())
    ready = asyncio.create_task(announce_ready(bus, "robot1", "scheduler", lambda: False))
    arrester = asyncio.create_task(watch_arrest())
    try:
        async with asyncio.timeout(60):
            async for _, st in statuses:
                seen.append(st)
                # Ask while s1 runs: the arrest point s2 is two epochs ahead, whatever the lag.
                if arrest_after and st.step_id == "s1" and st.status == "running":
                    await publish(
                        bus,
                        keys.scheduler_arrest("robot1"),
                        EarlyArrest(agent="robot1", plan_id=plan.plan_id, after_step=arrest_after),
                    )
                if st.step_id == until and st.status not in ("waiting", "running"):
                    break
        if arrest_after:
            await asyncio.wait_for(arrester, 10)
        await asyncio.sleep(settle)  # the world runs on (we keep acking): nothing may start
    finally:
        feeder.cancel()
        arrester.cancel()
        ready.cancel()
    return seen, report


def final(statuses: list[ActionStatus]) -> dict[str, str]:
    out: dict[str, str] = {}
    for st in statuses:
        out[st.step_id] = st.status
    return out


async def _run(
    router: str, spawn: object, plan: PartialPlan, settle: float = 0.0, **kw: str
) -> tuple[list[ActionStatus], ArrestReport | None, WorldStats]:
    env = {"CBDI_CONNECT": router}
    world = spawn(
        "world",
        "cbdi-world",
        "--simulator",
        "recycling",
        "--map",
        CORRIDOR,
        "--agent",
        "robot1",  # type: ignore[operator]
        "--lockstep",
        "--member",
        "robot1/executor",
        "--member",
        "robot1/scheduler",
        "--speed",
        "20",
        "--no-stop-when-done",
        "--max-time",
        "40",
        env=env,
    )
    bus = await open_bus(BusConfig(connect=(router,)))
    try:
        wait_for(lambda: "event=ready" in world.output(), what="world ready")
        player = asyncio.create_task(play_scheduler(bus, plan, settle=settle, **kw))
        await asyncio.sleep(0.3)
        executor = spawn("executor", "cbdi-executor", "--agent", "robot1", env=env)  # type: ignore[operator]
        seen, report = await player
        stats = await request(bus, keys.world_rpc("stats"), StatsRequest(), WorldStats)
        assert executor.alive()
        return seen, report, stats
    finally:
        await bus.close()


async def test_executor_runs_a_plan_in_the_world(router: str, spawn: object) -> None:
    seen, _, stats = await _run(router, spawn, corridor_plan())
    assert final(seen) == {f"s{i}": "succeeded" for i in range(1, 9)}
    robot = stats.agents[0]
    assert (
        robot.counts["moves"],
        robot.counts["pickups"],
        robot.counts["recycled"],
        robot.failed,
    ) == (
        6,
        1,
        1,
        0,
    )
    starts: dict[str, float] = {}
    for st in seen:
        if st.status == "running":
            starts.setdefault(st.step_id, st.time)
    assert not [st for st in seen if st.status == "running" and st.reason]  # no violation
    plan = {s.step_id: s.start for s in corridor_plan().steps}
    assert all(starts[i] >= plan[i] for i in plan)  # never before its time
    # The plan reaches the executor an epoch or two after it was made: every later step
    # then starts as soon as the one before it ends, back to back with no idle epoch.
    assert starts["s4"] - starts["s1"] == 3 and starts["s8"] - starts["s1"] == 9, starts


async def test_inapplicable_step_is_refused_before_dispatch(router: str, spawn: object) -> None:
    seen, _, stats = await _run(router, spawn, corridor_plan(pickup_cell="c_5_1"), until="s4")
    states = final(seen)
    assert states["s3"] == "succeeded" and states["s4"] == "refused"
    refusal = next(st for st in seen if st.step_id == "s4" and st.status == "refused")
    assert "(litter_pose plastic_4_1 c_5_1) does not hold" in refusal.reason
    assert stats.agents[0].counts["pickups"] == 0  # nothing was sent to the world


async def test_early_arrest_stops_after_the_running_step(router: str, spawn: object) -> None:
    seen, report, stats = await _run(
        router, spawn, corridor_plan(), arrest_after="s2", until="s2", settle=1.5
    )
    assert report is not None and report.last_step == "s2"
    assert final(seen)["s2"] == "succeeded"
    assert report.cancelled == ["s3", "s4", "s5", "s6", "s7", "s8"]
    assert stats.agents[0].counts["moves"] == 2 and stats.epoch >= 6  # s1, s2 done; nothing after
