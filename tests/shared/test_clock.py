"""Clocks: manual and simulated time wake sleepers in order and never go back."""

from __future__ import annotations

import asyncio

import pytest

from cbdi import keys
from cbdi.bus import LogSink, MemoryNetwork, publish
from cbdi.clock import ManualClock, SimClock, follow_world_clock
from cbdi.wire.world import Tick


async def test_manual_clock_wakes_sleepers_in_time_order() -> None:
    clock = ManualClock()
    woke: list[str] = []

    async def sleeper(name: str, when: float) -> None:
        await clock.sleep_until(when)
        woke.append(name)

    tasks = [asyncio.create_task(sleeper("late", 5)), asyncio.create_task(sleeper("early", 2))]
    await asyncio.sleep(0)
    clock.advance(1)
    await asyncio.sleep(0)
    assert woke == []
    clock.advance(1.5)
    await asyncio.sleep(0)
    assert woke == ["early"]
    clock.set(10)
    await asyncio.gather(*tasks)
    assert woke == ["early", "late"]


async def test_sleep_in_the_past_returns_at_once() -> None:
    clock = ManualClock(start=3.0)
    await asyncio.wait_for(clock.sleep_until(1.0), 0.5)
    await asyncio.wait_for(clock.sleep(0), 0.5)


def test_manual_clock_refuses_to_go_back() -> None:
    clock = ManualClock(start=2.0)
    with pytest.raises(ValueError):
        clock.set(1.0)


async def test_sim_clock_follows_ticks_and_ignores_stale_ones() -> None:
    clock = SimClock()
    clock.on_tick(0, 0.0)
    waiter = asyncio.create_task(clock.sleep(2.0))
    await asyncio.sleep(0)  # the sleeper reads now() = 0.0: it is due at 2.0
    clock.on_tick(1, 1.0)
    await asyncio.sleep(0)
    assert not waiter.done()
    clock.on_tick(1, 1.0)
    clock.on_tick(0, 0.0)
    assert clock.now() == 1.0 and clock.epoch == 1
    clock.on_tick(2, 2.0)
    await asyncio.wait_for(waiter, 0.5)


async def test_sim_clock_follows_the_world_over_the_bus() -> None:
    net = MemoryNetwork()
    world, agent = net.bus(), net.bus()
    clock = SimClock()
    sink = LogSink()
    follower = asyncio.create_task(follow_world_clock(agent, clock, sink))
    await asyncio.sleep(0)
    woke = asyncio.create_task(clock.sleep_until(2.0))
    await asyncio.sleep(0)
    for epoch in range(3):
        tick = Tick(epoch=epoch, time=float(epoch), epoch_duration=1.0, speed=1.0, lockstep=False)
        await publish(world, keys.world_stream("clock"), tick)
        await world.publish(keys.world_stream("clock"), b"garbage")
        await asyncio.sleep(0)
    await asyncio.wait_for(woke, 1)
    assert clock.now() == 2.0 and clock.epoch == 2 and len(sink.errors) == 3
    follower.cancel()
