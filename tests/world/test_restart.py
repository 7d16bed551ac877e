"""A world stopped mid-run and started again (`--restart 1`) goes on as if never stopped.

The paper's run in one process on the in-memory bus (as `tests/test_in_process.py`), in
lockstep: the world is stopped where it is at some epoch (its bus closes, its token
goes), and a new world service with the same settings and state file takes over. The
agents' services are never told: the executor asks the silent world again, every member
sends its latest ack again when the world's token comes back, the new world publishes
the epoch it was stopped in again (what a member had is not handled twice), and the
run ends with the undisturbed run's request trace, epoch for epoch.
"""

from __future__ import annotations

import asyncio
from dataclasses import replace
from pathlib import Path

import pytest
from test_in_process import MAP, agent_services

from cbdi import keys
from cbdi.bus import LogSink, MemoryNetwork, messages
from cbdi.clock import ManualClock
from cbdi.runtime.together import Together, TogetherService
from cbdi.wire import decode
from cbdi.wire.common import RunFinished
from cbdi.wire.world import Tick
from cbdi_world.service import WorldSettings, build_world, world_main

pytestmark = pytest.mark.timeout(300)


def world_of(settings: WorldSettings, network: MemoryNetwork, restart: int) -> Together:
    s = replace(settings, restart=restart)
    main = world_main(build_world(s), ManualClock())
    return Together([TogetherService("world", s, main)], network)


async def run(
    state: Path, stop_at: list[int], every: int = 20, resume: str = "on-restart"
) -> tuple[RunFinished, list[tuple[int, int]]]:
    """Run paper-7x7 to its end, the world stopped and restarted at each of `stop_at`
    (told it restarted, or with `resume="if-found"` not: a container's restart policy);
    return the world's last word and each tick's (epoch, sequence number)."""
    members = tuple(f"robot1/{c}" for c in ("planner", "scheduler", "executor"))
    settings = WorldSettings(
        simulator="recycling",
        map=MAP,
        agent=("robot1",),
        speed=0.0,
        lockstep=True,
        seed=1,
        max_time=300.0,
        member=members,
        option=("people_phase=true", "people_jitter=1"),
        state=str(state),
        state_every=every,
        resume=resume,
    )
    network = MemoryNetwork()
    ended = messages(network.bus(), keys.world_stream("events"), RunFinished, LogSink())
    ticks = messages(network.bus(), keys.world_stream("clock"), Tick, LogSink())
    agents = Together(agent_services("robot1"), network)
    async with asyncio.timeout(240), asyncio.TaskGroup() as tg:
        tg.create_task(agents.run())
        world = world_of(settings, network, 0)
        running = tg.create_task(world.run())
        for restart, epoch in enumerate(stop_at, start=1):
            async for _, tick in ticks:
                if tick.epoch >= epoch:
                    break
            world.stop()  # where it is: between two awaits, as a kill would find it
            await running
            world = world_of(settings, network, restart if resume == "on-restart" else 0)
            running = tg.create_task(world.run())
        _, finished = await anext(ended)
        agents.stop()
        world.stop()
    clock = keys.world_stream("clock")
    published = [
        (decode(s.payload, Tick).epoch, s.seq) for s in network.published if s.key == clock
    ]
    return finished, published


# Saved whole every epoch, or every 20 (then the steps since are replayed: 10 and 3).
@pytest.mark.parametrize("every", [1, 20])
async def test_a_restarted_world_goes_on_with_the_same_run(tmp_path: Path, every: int) -> None:
    plain, _ = await run(tmp_path / "plain.state", [])
    assert plain.reason == "done" and plain.requests > 0
    stopped, ticks = await run(tmp_path / "world.state", [10, 23], every)
    assert stopped.reason == "done" and not stopped.stalls
    assert (stopped.trace_digest, stopped.epoch) == (plain.trace_digest, plain.epoch)
    # Three worlds (each one's ticks numbered from 1), every epoch published once but
    # the two the world was stopped in: its restart publishes them again (a crash may
    # have lost them in Zenoh's queue), and the members take the repeat as had.
    expected = sorted([*range(plain.epoch + 1), 10, 23])
    assert [epoch for epoch, _ in ticks] == expected
    assert [epoch for epoch, seq in ticks if seq == 1] == [0, 10, 23]


async def test_a_world_restarted_untold_goes_on_from_the_state_file_it_finds(
    tmp_path: Path,
) -> None:
    """`--resume if-found` (`cbdi compose`: the file in the container's own volume): the
    restarted container's world is not told it restarted; it goes on from the file it
    finds, and removes the file once the run ended (a container started again for a
    new run must not go on with this one)."""
    plain, _ = await run(tmp_path / "plain.state", [])
    state = tmp_path / "world.state"
    stopped, ticks = await run(state, [10, 23], 20, resume="if-found")
    assert (stopped.trace_digest, stopped.epoch) == (plain.trace_digest, plain.epoch)
    assert [epoch for epoch, seq in ticks if seq == 1] == [0, 10, 23]
    assert not state.exists()
