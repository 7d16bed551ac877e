"""The world and a scripted agent as real processes over a real `cbdi router`.

The agent is driven along a path, picks up and recycles one litter item; the test then
asks the world for its statistics over Zenoh, as any client would.
"""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest
from cbdi_recycling.wire import grid_map

from cbdi import keys
from cbdi.bus import BusConfig, LogSink, messages, open_bus, request
from cbdi.wire.common import RunFinished
from cbdi.wire.world import StatsRequest, WorldInfo, WorldInfoRequest, WorldStats
from tests_support import REPO, wait_for

pytestmark = pytest.mark.e2e

CORRIDOR = str(REPO / "domains/recycling/maps/corridor-6x3.toml")
PATH = "move:2,1 move:3,1 move:4,1 pickup move:3,1 move:2,1 move:1,1 recycle"


async def _finished_and_stats(endpoint: str) -> tuple[RunFinished, WorldStats, WorldInfo]:
    bus = await open_bus(BusConfig(connect=(endpoint,)))
    try:
        events = messages(bus, keys.world_stream("events"), RunFinished, LogSink())
        info = await request(bus, keys.world_rpc("info"), WorldInfoRequest(), WorldInfo, timeout=5)
        _, finished = await asyncio.wait_for(anext(events), 60)
        stats = await request(
            bus, keys.world_rpc("stats"), StatsRequest(agent="robot1"), WorldStats, timeout=5
        )
        return finished, stats, info
    finally:
        await bus.close()


@pytest.mark.parametrize("pacing", [["--lockstep", "--speed", "0"], ["--speed", "25"]])
async def test_scripted_agent_recycles_one_item(
    router: str, spawn: object, pacing: list[str]
) -> None:
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
        "--stop-when-done",
        *pacing,
        env=env,
    )
    wait_for(lambda: "event=ready" in world.output(), what="world ready")
    waiter = asyncio.create_task(_finished_and_stats(router))
    await asyncio.sleep(0.5)
    agent = spawn(
        "agent",
        "cbdi-scripted-agent",
        "--agent",
        "robot1",
        "--script",
        PATH,
        env=env,
    )
    finished, stats, info = await waiter
    assert finished.reason == "done"
    assert finished.epoch == 12  # 6 moves of 1 + pickup 3 + recycle 3 epochs
    robot = stats.agents[0]
    assert (
        robot.agent,
        robot.counts["moves"],
        robot.counts["pickups"],
        robot.counts["recycled"],
    ) == (
        "robot1",
        6,
        1,
        1,
    )
    assert (robot.failed, robot.rejected) == (0, 0)
    assert (
        stats.totals["litter_recycled"] == 1
        and stats.totals["litter_on_ground"] == 0
        and stats.done
    )
    assert grid_map(info).width == 6 and info.agents == ["robot1"]
    assert world.alive() and agent.alive()  # the world keeps serving after the run


async def test_failed_move_is_reported_and_counted(router: str, spawn: object) -> None:
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
        "--speed",
        "0",
        "--max-time",
        "6",
        env=env,
    )
    wait_for(lambda: "event=ready" in world.output(), what="world ready")
    agent = spawn(
        "agent",
        "cbdi-scripted-agent",
        "--agent",
        "robot1",
        "--script",
        "move:1,0",
        "--retries",
        "2",
        env=env,
    )
    wait_for(lambda: not agent.alive(), timeout=30, what="agent to give up")
    assert "reason=wall" in agent.output()
    assert agent.popen.returncode == 1
    bus = await open_bus(BusConfig(connect=(router,)))
    try:
        stats = await request(bus, keys.world_rpc("stats"), StatsRequest(), WorldStats, timeout=5)
    finally:
        await bus.close()
    assert stats.agents[0].failed == 2 and stats.agents[0].counts["moves"] == 0


def test_broken_map_is_rejected_with_file_field_and_reason(tmp_path: Path, spawn: object) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "bad"\ngrid = """\nBA.\n.x.\n"""\n')
    proc = spawn("world", "cbdi-world", "--simulator", "recycling", "--map", str(bad))  # type: ignore[operator]
    wait_for(lambda: not proc.alive(), what="world to refuse the map")
    assert proc.popen.returncode == 2
    assert f"{bad}: grid row 1 column 1: unknown cell 'x'" in proc.output()
