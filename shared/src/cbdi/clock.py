"""The injected clock. Logic asks a `Clock` for time and never calls time or sleep itself.

- `WallClock`: monotonic wall time, for tools that really wait.
- `ManualClock`: time moves only when a test says so (`advance`, `set`), trio-style.
- `SimClock`: follows the world's published `Tick`s, so agents live in simulated time and
  runs are reproducible at any `--speed`.
"""

from __future__ import annotations

import asyncio
import heapq
import itertools
import time
from typing import Protocol

from cbdi import keys
from cbdi.bus.base import Bus
from cbdi.bus.typed import ErrorSink, messages
from cbdi.wire.world import Tick

__all__ = ["Clock", "ManualClock", "SimClock", "WallClock", "follow_world_clock"]


class Clock(Protocol):
    """A source of time in seconds (wall or simulated)."""

    def now(self) -> float:
        """Return the current time."""
        ...

    async def sleep_until(self, when: float) -> None:
        """Return once `now() >= when`."""
        ...

    async def sleep(self, delay: float) -> None:
        """Return once `delay` seconds have passed on this clock."""
        ...


class WallClock:
    """Monotonic wall time (seconds since an arbitrary origin)."""

    def now(self) -> float:
        return time.monotonic()

    async def sleep_until(self, when: float) -> None:
        await asyncio.sleep(max(0.0, when - self.now()))

    async def sleep(self, delay: float) -> None:
        await asyncio.sleep(max(0.0, delay))


class _SteppedClock:
    """A clock whose time only moves when `_set` is called; sleepers wake in time order."""

    def __init__(self, start: float = 0.0) -> None:
        self._now = start
        self._sleepers: list[tuple[float, int, asyncio.Future[None]]] = []
        self._seq = itertools.count()

    def now(self) -> float:
        return self._now

    async def sleep_until(self, when: float) -> None:
        if when <= self._now:
            await asyncio.sleep(0)
            return
        future: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        heapq.heappush(self._sleepers, (when, next(self._seq), future))
        await future

    async def sleep(self, delay: float) -> None:
        await self.sleep_until(self._now + max(0.0, delay))

    def _set(self, when: float) -> None:
        if when < self._now:
            raise ValueError(f"clock cannot go back from {self._now} to {when}")
        self._now = when
        while self._sleepers and self._sleepers[0][0] <= when:
            _, _, future = heapq.heappop(self._sleepers)
            if not future.done():
                future.set_result(None)


class ManualClock(_SteppedClock):
    """A clock for tests: time stands still until `advance` or `set`."""

    def advance(self, delta: float) -> None:
        """Move time forward by `delta` and wake every sleeper that is due."""
        self._set(self._now + delta)

    def set(self, when: float) -> None:
        """Move time forward to `when` and wake every sleeper that is due."""
        self._set(when)


class SimClock(_SteppedClock):
    """Simulated time as published by the world; `epoch` is the last tick seen."""

    def __init__(self) -> None:
        super().__init__(0.0)
        self.epoch = -1

    def on_tick(self, epoch: int, when: float) -> None:
        """Follow a world tick; older or duplicate ticks are ignored."""
        if epoch <= self.epoch:
            return
        self.epoch = epoch
        self._set(max(when, self._now))


async def follow_world_clock(bus: Bus, clock: SimClock, sink: ErrorSink) -> None:
    """Keep `clock` on the world's time: apply every `Tick` published on the clock key."""
    async for _, tick in messages(bus, keys.world_stream("clock"), Tick, sink):
        clock.on_tick(tick.epoch, tick.time)
