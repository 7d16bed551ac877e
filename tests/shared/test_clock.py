"""Clocks: manual and simulated time wake sleepers in order and never go back."""

from __future__ import annotations

import asyncio

import pytest

from cbdi.clock import ManualClock, SimClock


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
