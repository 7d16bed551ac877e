"""A plain text view of the world: one character grid per epoch.

`render` is pure (info + snapshot -> text); `follow_text` draws every snapshot it hears;
`cbdi view` runs it against a live run.
"""

from __future__ import annotations

import asyncio
import string
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TextIO

import uvloop

from cbdi import keys
from cbdi.bus import LogSink, messages, request
from cbdi.bus.base import Bus
from cbdi.bus.zenoh_bus import open_bus
from cbdi.errors import CbdiError
from cbdi.runtime import ServiceSettings, load_config
from cbdi.wire.world import WorldInfo, WorldInfoRequest, WorldSnapshot

__all__ = ["follow_text", "main", "render"]

_AGENT_MARKS = string.digits[1:] + string.ascii_uppercase


def render(info: WorldInfo, snap: WorldSnapshot) -> str:
    """Draw the grid: `#` wall, `B` bin, `@` person, `*` litter, 1-9/A-Z robots."""
    grid = [["." for _ in range(info.width)] for _ in range(info.height)]
    for x, y in info.walls:
        grid[y][x] = "#"
    for b in info.bins:
        grid[b.cell[1]][b.cell[0]] = "B"
    for item in snap.litter:
        grid[item.cell[1]][item.cell[0]] = "*" if item.known else "+"
    for p in snap.people:
        grid[p.cell[1]][p.cell[0]] = "@"
    legend = []
    for i, a in enumerate(snap.agents):
        mark = _AGENT_MARKS[i % len(_AGENT_MARKS)]
        grid[a.cell[1]][a.cell[0]] = mark
        load = f" holding {len(a.holding)}" if a.holding else ""
        doing = f" {a.action}" if a.action else ""
        legend.append(f"{mark}={a.name}{load}{doing}")
    header = (
        f"epoch {snap.epoch}  t={snap.time:.1f}  litter on ground {len(snap.litter)}"
        f"  recycled {len(snap.recycled)}"
    )
    rows = [" ".join(row) for row in grid]
    return "\n".join([header, *rows, "  ".join(legend)])


async def world_info(bus: Bus, timeout: float = 10.0) -> WorldInfo:
    """Ask the world for its static part, retrying while it is not up yet."""
    async with asyncio.timeout(timeout):
        while True:
            try:
                return await request(bus, keys.world_rpc("info"), WorldInfoRequest(), WorldInfo)
            except CbdiError:
                await asyncio.sleep(0.2)


async def follow_text(bus: Bus, out: TextIO, frames: int = 0) -> None:
    """Print a frame for every world snapshot (clearing the screen on a terminal).

    With `frames` > 0, stop after that many frames.
    """
    snaps = messages(bus, keys.world_stream("snapshot"), WorldSnapshot, LogSink())
    info = await world_info(bus)
    clear = "\x1b[2J\x1b[H" if out.isatty() else ""
    async for _, snap in snaps:
        out.write(f"{clear}{render(info, snap)}\n\n")
        out.flush()
        frames -= 1
        if frames == 0:
            return


@dataclass(frozen=True)
class ViewSettings(ServiceSettings):
    """`cbdi view` takes the bus settings only."""

    frames: int = field(default=0, metadata={"help": "stop after this many frames (0: never)"})


def main(argv: Sequence[str] | None = None) -> int:
    """Run `cbdi view` until Ctrl-C."""
    import sys

    settings = load_config(
        ViewSettings,
        argv,
        prog="cbdi view",
        section="view",
        description="Show a running world as text.",
    )

    async def run() -> None:
        bus = await open_bus(settings.bus_config())
        try:
            await follow_text(bus, sys.stdout, settings.frames)
        finally:
            await bus.close()

    try:
        uvloop.run(run())
    except KeyboardInterrupt:
        pass
    except (CbdiError, TimeoutError) as exc:
        print(f"cbdi view: {exc or 'no world answered'}", file=sys.stderr)
        return 1
    return 0
