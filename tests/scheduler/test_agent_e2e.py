"""Scheduler and executor as real processes with the world over Zenoh: a recycler agent
that knows one litter item takes up the desire, asks for a plan, runs it, and sees its goal
achieved. The test stands in for the planner (issue 4): it answers the search request.
"""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest

from cbdi import keys
from cbdi.bus import BusConfig, LogSink, messages, open_bus, publish, request
from cbdi.wire.agent import DesireEvent, PartialPlan
from cbdi.wire.planner import SearchRequest
from cbdi.wire.world import StatsRequest, WorldStats
from tests_support import REPO, wait_for

pytestmark = pytest.mark.e2e
CORRIDOR = str(REPO / "domains/recycling/maps/corridor-6x3.toml")
RECYCLER = (REPO / "domains/recycling/agents/recycler.toml").read_text()


def agent_file(tmp_path: Path) -> Path:
    known = RECYCLER.replace(
        '  "(map_loaded)",\n',
        '  "(map_loaded)", "plastic_4_1 - plastic", "(litter_pose plastic_4_1 c_4_1)",\n',
        1,
    )
    assert known != RECYCLER
    path = tmp_path / "recycler.toml"
    path.write_text(
        known.replace(
            'domain = "../pddl/domain.pddl"',
            f'domain = "{REPO}/domains/recycling/pddl/domain.pddl"',
        )
    )
    return path


def corridor_plan(start: float) -> PartialPlan:
    from test_executor_e2e import corridor_plan as plan  # the same eight steps

    p = plan()
    steps = [
        s.__class__(**{**{f: getattr(s, f) for f in s.__struct_fields__}, "start": s.start + start})
        for s in p.steps
    ]
    return PartialPlan(agent="robot1", plan_id="p1", baseline="", steps=steps, complete=True)


async def test_agent_pursues_its_desire_to_the_end(
    router: str, spawn: object, tmp_path: Path
) -> None:
    env = {"CBDI_CONNECT": router}
    recording = tmp_path / "agent.mcap"
    monitor = spawn("monitor", "cbdi-monitor", "--output", str(recording), env=env)  # type: ignore[operator]
    wait_for(lambda: "event=ready" in monitor.output(), what="monitor ready")
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
        "--speed",
        "10",
        "--stop-when-done",
        env=env,
    )
    bus = await open_bus(BusConfig(connect=(router,)))
    try:
        sink = LogSink()
        searches = messages(bus, keys.planner_requests("robot1"), SearchRequest, sink)
        desires = messages(bus, keys.scheduler_desires("robot1"), DesireEvent, sink)
        wait_for(lambda: "event=ready" in world.output(), what="world ready")
        spawn(
            "scheduler",
            "cbdi-scheduler",
            "--agent",
            "robot1",  # type: ignore[operator]
            "--agent-file",
            str(agent_file(tmp_path)),
            env=env,
        )
        spawn("executor", "cbdi-executor", "--agent", "robot1", env=env)  # type: ignore[operator]
        async with asyncio.timeout(60):
            _, search = await anext(searches)
            assert search.kind == "start" and search.goal == [["recycled", "plastic_4_1"]]
            await publish(bus, keys.planner_plans("robot1"), corridor_plan(0.0), block=True)
            seen = []
            while ("recycle", "achieved") not in seen:
                _, event = await anext(desires)
                seen.append((event.desire, event.event))
            _, cancel = await anext(searches)
            assert cancel.kind == "cancel" and cancel.request_id == search.request_id
        recycle = [s for s in seen if s[0] == "recycle"]  # make_way comes and goes too
        assert recycle[:2] == [("recycle", "added"), ("recycle", "activated")]
        stats = await request(bus, keys.world_rpc("stats"), StatsRequest(), WorldStats)
        assert stats.totals["litter_recycled"] == 1 and stats.agents[0].counts["moves"] == 6
    finally:
        await bus.close()
    await asyncio.sleep(0.3)
    monitor.stop()
    from cbdi_monitor.inspect import inspect_messages
    from cbdi_monitor.reader import read_messages
    from cbdi_monitor.view import convert

    robot = inspect_messages(read_messages(recording)).agents["robot1"]
    # Two goals at least: recycling, then making way from the bin (its search gets no
    # plan here). The test sends its plan in wall time: while it is on its way, the idle
    # robot may also come to explore (and reach) a cell it passes.
    assert (robot.plans, robot.actions["move:succeeded"]) == (1, 6) and robot.goals_achieved >= 2
    assert convert(recording, tmp_path / "agent.rrd") > 0
