"""A third domain, without a floor of cells: a greenhouse whose map is places and links
(tests/world/greenhouse), registered as an installed package registers its entry
points, hosted by the world service on the in-memory bus in lockstep with a gardener
robot, recorded by the monitor; its view has places and links and `cbdi inspect`
reports its own counters."""

from __future__ import annotations

import asyncio
import json
import tomllib
from collections import deque
from collections.abc import AsyncIterator
from pathlib import Path

import pytest

from cbdi import keys
from cbdi.bus import LogSink, MemoryNetwork, messages
from cbdi.bus.base import Bus
from cbdi.bus.typed import request
from cbdi.clock import ManualClock
from cbdi.lockstep import announce_ready, send_ack
from cbdi.runtime.together import Together, TogetherService
from cbdi.view import render, world_info
from cbdi.wire.base import decode
from cbdi.wire.common import RunFinished
from cbdi.wire.world import ActionReply, ActionRequest, Sensed, Tick, WorldInfo, WorldSnapshot
from cbdi_monitor import inspect
from cbdi_monitor.reader import read_messages
from cbdi_monitor.service import MonitorSettings, monitor_main
from cbdi_world.service import WorldSettings, build_world, world_main

HERE = Path(__file__).parent / "greenhouse"


@pytest.fixture
def installed(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Register the greenhouse's entry points (its pyproject.toml) as `pip install`
    would: a dist-info folder on the path, the package's module beside it."""
    project = tomllib.loads((HERE / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    info = tmp_path / "site" / f"cbdi_greenhouse-{project['version']}.dist-info"
    info.mkdir(parents=True)
    info.joinpath("METADATA").write_text(
        f"Metadata-Version: 2.1\nName: {project['name']}\nVersion: {project['version']}\n"
    )
    groups = project["entry-points"]
    info.joinpath("entry_points.txt").write_text(
        "".join(
            f"[{group}]\n" + "".join(f"{n} = {target}\n" for n, target in points.items())
            for group, points in groups.items()
        )
    )
    monkeypatch.syspath_prepend(str(HERE))
    monkeypatch.syspath_prepend(str(tmp_path / "site"))


def next_hop(info: WorldInfo, here: str, goals: set[str]) -> str:
    """The first place on a shortest way from `here` to one of `goals`, along links."""
    assert info.view is not None
    seen, queue = {here: here}, deque([here])
    while queue:
        place = queue.popleft()
        if place in goals:
            while seen[place] != here:
                place = seen[place]
            return place
        for link in info.view.links:
            for a, b in ((link.a, link.b), (link.b, link.a)):
                if a == place and b not in seen:
                    seen[b] = place
                    queue.append(b)
    raise AssertionError(f"no way from {here} to {goals}")


async def gardener(bus: Bus, agent: str = "robot1") -> None:
    """A scripted robot, a lockstep member: each epoch, water a dry plant where it
    stands, else walk towards one, then acknowledge the epoch."""
    percepts = messages(bus, keys.world_percepts(agent), Sensed, LogSink())
    ticks = messages(bus, keys.world_stream("clock"), Tick, LogSink())

    started = False
    announcing = asyncio.create_task(announce_ready(bus, agent, "gardener", lambda: started))
    try:
        await anext(ticks)
        started = True
        await water(bus, agent, percepts)
    finally:
        announcing.cancel()


async def water(bus: Bus, agent: str, percepts: AsyncIterator[tuple[str, Sensed]]) -> None:
    """Act on each epoch's percepts, then acknowledge it."""
    info = await world_info(bus)
    plants = {f[1]: f[2] for f in info.facts if f[0] == "plant_at"}
    n = 0
    async for _, sensed in percepts:
        facts = {tuple(a) for a in sensed.add}
        here = next(f[2] for f in facts if f[0] == "at")
        dry = {f[1] for f in facts if f[0] == "dry"}
        if ("idle", agent) in facts and dry:
            n += 1
            dry_here = [p for p in sorted(dry) if plants[p] == here]
            if dry_here:
                args = [agent, dry_here[0], here]
                action = "water"
            else:
                args = [agent, here, next_hop(info, here, {plants[p] for p in dry})]
                action = "go"
            ask = ActionRequest(agent=agent, action=action, request_id=f"{agent}-{n}", args=args)
            reply = await request(bus, keys.world_act(agent), ask, ActionReply)
            assert reply.accepted, reply.reason
        await send_ack(bus, agent, "gardener", sensed.epoch)


async def test_a_greenhouse_of_places_and_links_runs_in_the_world_host(
    installed: None, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    recording = tmp_path / "greenhouse.mcap"
    settings = WorldSettings(
        simulator="greenhouse",
        map=str(HERE / "greenhouse.toml"),
        agent=("robot1",),
        speed=0.0,
        lockstep=True,
        max_time=100.0,
        member=("robot1/gardener",),
    )
    monitor = MonitorSettings(output=str(recording), drain=0.1)
    network = MemoryNetwork()
    ended = messages(network.bus(), keys.world_stream("events"), RunFinished, LogSink())
    together = Together(
        [
            TogetherService("monitor", monitor, monitor_main(monitor)),
            TogetherService("world", settings, world_main(build_world(settings), ManualClock())),
        ],
        network,
    )

    async def run() -> RunFinished:
        robot = asyncio.create_task(gardener(network.bus()))
        end = asyncio.ensure_future(anext(ended))
        try:
            async with asyncio.timeout(60):
                await asyncio.wait({robot, end}, return_when=asyncio.FIRST_COMPLETED)
            if robot.done():
                robot.result()  # what went wrong with it, if anything
            _, finished = await end
            return finished
        finally:
            robot.cancel()
            together.stop()

    codes, finished = await asyncio.gather(together.run(), run())
    assert all(code == 0 for code in codes.values()), codes
    assert finished.reason == "done" and finished.requests > 0

    recorded = list(read_messages(recording))
    infos = [m for m in recorded if m.schema == "cbdi.world.WorldInfo/1"]
    info = decode(infos[0].payload, WorldInfo, infos[0].key)
    assert info.simulator == "greenhouse" and info.map == b""
    assert info.view is not None and info.view.layers == []  # no floor of cells
    assert [p.name for p in info.view.places] == ["shed", "beds", "pond"]
    assert [(link.a, link.b) for link in info.view.links] == [
        ("shed", "beds"),
        ("beds", "pond"),
        ("shed", "pond"),
    ]
    snaps = [m for m in recorded if m.schema == "cbdi.world.WorldSnapshot/1"]
    last = decode(snaps[-1].payload, WorldSnapshot, snaps[-1].key)
    frame = render(info, last).splitlines()
    assert frame[1].startswith("o - - - - - ") and frame[-1] == (
        "links: shed-beds  beds-pond  shed-pond"
    )
    assert frame[-2] == "places: shed 0,0  beds 6,0  pond 6,4"

    assert inspect.main([str(recording), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["simulator"] == "greenhouse"
    robot = report["agents"]["robot1"]
    assert robot["counters"]["waterings"] == 4 and robot["counters"]["walks"] >= 2
    assert inspect.main([str(recording)]) == 0
    text = capsys.readouterr().out
    assert "agent robot1: waterings=4 walks=" in text and "moves=" not in text
