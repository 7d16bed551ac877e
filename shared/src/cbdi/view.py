"""A plain text view of the world: one character grid per epoch.

`render` is pure (info + snapshot + what each agent intends -> text); `follow_text` draws
every snapshot it hears, with the intentions the agents' schedulers report (desire
events); `cbdi view` runs it against a live run.
"""

from __future__ import annotations

import asyncio
import string
from collections.abc import AsyncIterator, Coroutine, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, TextIO

import uvloop

from cbdi import keys
from cbdi.bus import LogSink, messages, request
from cbdi.bus.base import Bus
from cbdi.bus.zenoh_bus import open_bus
from cbdi.errors import CbdiError
from cbdi.runtime import ServiceSettings, load_config
from cbdi.security.login import config_as
from cbdi.security.policy import VIEWER
from cbdi.wire.agent import DesireEvent
from cbdi.wire.world import MapView, WorldInfo, WorldInfoRequest, WorldSnapshot

__all__ = ["Intentions", "follow_text", "main", "render", "text_view"]

_AGENT_MARKS = string.digits[1:] + string.ascii_uppercase


def render(info: WorldInfo, snap: WorldSnapshot, intents: Mapping[str, str] | None = None) -> str:
    """Draw the map: its static layers (`WorldInfo.view`: `#` walls and whatever glyph
    each of the domain's layers has), a graph's links as lines (`- | / \\`) and places
    (`o`, or their own glyph), `@` person (a moving obstacle), `*` an item known from
    the start, `+` one found, 1-9/A-Z robots; then the graph's places and links by name,
    and what each agent intends (`intents`: agent -> text), if known. A map without a
    view is drawn as big as the cells the snapshot holds."""
    width, height = _extent(info, snap)
    grid = [["." for _ in range(width)] for _ in range(height)]
    if info.view is not None:
        _draw_graph(grid, info.view)
    for layer in info.view.layers if info.view else []:  # over the graph: walls hide it
        for x, y in layer.cells:
            _mark(grid, (x, y), layer.glyph)
    for item in snap.items:
        _mark(grid, item.cell, "*" if item.known else "+")
    for p in snap.people:
        _mark(grid, p.cell, "@")
    legend = []
    for i, a in enumerate(snap.agents):
        mark = _AGENT_MARKS[i % len(_AGENT_MARKS)]
        _mark(grid, a.cell, mark)
        load = f" carrying {len(a.load)}" if a.load else ""
        doing = f" {a.action}" if a.action else ""
        legend.append(f"{mark}={a.name}{load}{doing}")
    header = (
        f"epoch {snap.epoch}  t={snap.time:.1f}  items on the map {len(snap.items)}"
        f"  completed {len(snap.completed)}"
    )
    rows = [" ".join(row) for row in grid]
    graph = _graph_legend(info.view) if info.view is not None else []
    intending = [f"{a}: {text}" for a, text in sorted((intents or {}).items())]
    return "\n".join([header, *rows, "  ".join(legend), *graph, *intending])


# A graph of more places than this is drawn, not listed (a courier floor's every cell).
_LISTED_PLACES = 24


def _graph_legend(view: MapView) -> list[str]:
    """Name a small graph's places (where each is drawn) and links; count a big one's."""
    if not view.places:
        return []
    if len(view.places) > _LISTED_PLACES:
        return [f"graph: {len(view.places)} places, {len(view.links)} links"]
    places = "  ".join(f"{p.name} {int(p.at[0])},{int(p.at[1])}" for p in view.places)
    links = "  ".join(f"{link.a}-{link.b}" for link in view.links)
    return [f"places: {places}", *([f"links: {links}"] if links else [])]


def _draw_graph(grid: list[list[str]], view: MapView) -> None:
    """Draw each link as a line over the floor between its places, then the places."""
    at = {p.name: (int(p.at[0]), int(p.at[1])) for p in view.places}
    for link in view.links:
        (x0, y0), (x1, y1) = at[link.a], at[link.b]
        dx, dy = x1 - x0, y1 - y0
        glyph = "|" if dx == 0 else "-" if dy == 0 else "\\" if (dx > 0) == (dy > 0) else "/"
        steps = max(abs(dx), abs(dy))
        for i in range(1, steps):  # the cells strictly between the two places
            cell = (x0 + round(i * dx / steps), y0 + round(i * dy / steps))
            if _at(grid, cell) == ".":
                _mark(grid, cell, glyph)
    for p in view.places:
        _mark(grid, at[p.name], p.glyph)


def _at(grid: list[list[str]], cell: tuple[int, int]) -> str:
    x, y = cell
    return grid[y][x] if 0 <= y < len(grid) and 0 <= x < len(grid[y]) else ""


def _extent(info: WorldInfo, snap: WorldSnapshot) -> tuple[int, int]:
    """The map's size: its view's, or what holds every cell of the snapshot."""
    if info.view is not None:
        return info.view.width, info.view.height
    cells = [a.cell for a in snap.agents] + [p.cell for p in snap.people]
    cells += [i.cell for i in snap.items]
    return max((c[0] + 1 for c in cells), default=1), max((c[1] + 1 for c in cells), default=1)


def _mark(grid: list[list[str]], cell: tuple[int, int], glyph: str) -> None:
    """Put `glyph` on `cell`, if it is on the grid."""
    x, y = cell
    if 0 <= y < len(grid) and 0 <= x < len(grid[y]):
        grid[y][x] = glyph


class Intentions:
    """What each agent pursues, from its scheduler's desire events."""

    def __init__(self) -> None:
        self.current: dict[str, str] = {}  # agent -> desire name
        self.text: dict[str, str] = {}

    def on_event(self, e: DesireEvent) -> None:
        goal = " ".join("(" + " ".join(g) + ")" for g in e.goal)
        pursued = self.current.get(e.agent) == e.desire
        if e.event == "activated" or (e.event in ("boosted", "reduced") and pursued):
            self.current[e.agent] = e.desire
            self.text[e.agent] = f"intends {e.desire} {goal}"
        elif e.event in ("achieved", "dropped") and pursued:
            del self.current[e.agent]
            why = f" ({e.reason})" if e.reason else ""
            self.text[e.agent] = f"{e.event} {e.desire}{why}"


async def world_info(bus: Bus, timeout: float = 10.0) -> WorldInfo:
    """Ask the world for its static part, retrying while it is not up yet."""
    async with asyncio.timeout(timeout):
        while True:
            try:
                return await request(bus, keys.world_rpc("info"), WorldInfoRequest(), WorldInfo)
            except CbdiError:
                await asyncio.sleep(0.2)


def text_view(bus: Bus, out: TextIO, frames: int = 0) -> Coroutine[Any, Any, None]:
    """Subscribe now (so nothing from here on is missed) and return the coroutine that
    prints a frame for every world snapshot (clearing the screen on a terminal), with what
    each agent intends. With `frames` > 0 it stops after that many frames."""
    snaps = messages(bus, keys.world_stream("snapshot"), WorldSnapshot, LogSink())
    events = messages(bus, keys.agent_stream("*", "scheduler", "desires"), DesireEvent, LogSink())
    return _draw(bus, snaps, events, out, frames)


async def follow_text(bus: Bus, out: TextIO, frames: int = 0) -> None:
    """Print a frame for every world snapshot from now on (see `text_view`)."""
    await text_view(bus, out, frames)


async def _draw(
    bus: Bus,
    snaps: AsyncIterator[tuple[str, WorldSnapshot]],
    events: AsyncIterator[tuple[str, DesireEvent]],
    out: TextIO,
    frames: int,
) -> None:
    intentions = Intentions()

    async def follow() -> None:
        async for _, event in events:
            intentions.on_event(event)

    follower = asyncio.create_task(follow())
    try:
        info = await world_info(bus)
        clear = "\x1b[2J\x1b[H" if out.isatty() else ""
        async for _, snap in snaps:
            out.write(f"{clear}{render(info, snap, intentions.text)}\n\n")
            out.flush()
            frames -= 1
            if frames == 0:
                return
    finally:
        follower.cancel()


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
        cfg = settings.bus_config()
        if not settings.credentials:  # a secured local run's viewer, if there is one
            found = config_as(VIEWER, settings.connect)
            cfg = replace(cfg, user=found.user, password=found.password)
        bus = await open_bus(cfg)
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
