"""The recycling domain's wire types: the grid's percepts and its map.

`Percepts`, the square a robot senses around it, is registered in entry-point group
`cbdi.percepts`, so the generic services decode it on an agent's percepts key and pass
it on as a `Percept` (its agent, epoch, time and `sent` are all they read); the
recycling knowledge (`cbdi_recycling.knowledge`) and the scripted robot read the rest.
`GridMap` is the grid's own map, which the world carries in `WorldInfo.map` (`grid_map`
reads it back): the views draw the grid from `WorldInfo.view` and never read it.
"""

from __future__ import annotations

from typing import Annotated

import msgspec

from cbdi.errors import WireError
from cbdi.wire.base import Message, decode, encode
from cbdi.wire.fields import AgentName, Cell, Count, Many, Symbol
from cbdi.wire.world import ItemView, MapLayer, MapView, Percept, WorldInfo

__all__ = ["AgentSeen", "BinView", "GridMap", "Percepts", "grid_map", "map_view", "with_map"]


class AgentSeen(Message, frozen=True, tag="cbdi.recycling.AgentSeen/1"):
    """Another agent standing on a cell of the sensed square."""

    name: AgentName
    cell: Cell


class Percepts(Percept, frozen=True, kw_only=True, tag="cbdi.recycling.Percepts/1"):
    """What one agent senses this epoch in the (2d+1)x(2d+1) square around it.

    `free` cells are inside the map and hold no wall, bin, person or agent; `blocked` are
    the other in-map cells of the square (the agent's own cell is reported as blocked by
    itself only in `position`). `items` lists the items lying in the square, `holding`
    those the agent carries, `others` the other agents standing in it (which of the
    `blocked` cells they hold).
    """

    position: Cell
    depth: Annotated[int, msgspec.Meta(ge=0, le=1000)]
    free: Many[Cell]
    blocked: Many[Cell]
    items: Many[ItemView]
    holding: Many[Symbol]
    others: Many[AgentSeen] = []


class BinView(Message, frozen=True, tag="cbdi.recycling.BinView/1"):
    """One bin: a fixed drop-off place."""

    name: Symbol
    cell: Cell


class GridMap(Message, frozen=True, tag="cbdi.recycling.GridMap/1"):
    """The grid's static part: size, walls, bins, how many items a robot carries, and
    each agent's sensing depth."""

    width: Annotated[int, msgspec.Meta(ge=1, le=10_000)]
    height: Annotated[int, msgspec.Meta(ge=1, le=10_000)]
    walls: Many[Cell]
    bins: Many[BinView]
    capacity: Count
    detection_depth: Annotated[dict[AgentName, Count], msgspec.Meta(max_length=10_000)]


def map_view(grid: GridMap) -> MapView:
    """How the views draw the grid: walls (`#`), then bins (`B`, labelled)."""
    walls = MapLayer(name="walls", cells=list(grid.walls))
    bins = MapLayer(
        name="bins",
        cells=[b.cell for b in grid.bins],
        labels=[b.name for b in grid.bins],
        glyph="B",
        colour=(40, 140, 60),
        size=0.8,
    )
    return MapView(width=grid.width, height=grid.height, layers=[walls, bins])


def with_map(info: WorldInfo, grid: GridMap) -> WorldInfo:
    """`info` carrying `grid` (in `map`) and its drawing (in `view`)."""
    return msgspec.structs.replace(info, view=map_view(grid), map=encode(grid))


def grid_map(info: WorldInfo) -> GridMap:
    """The grid map `info` carries; a WireError if it carries none (another domain's)."""
    if not info.map:
        raise WireError(
            "cbdi.recycling.GridMap/1", f"world info of {info.simulator or 'a world'}: no grid map"
        )
    return decode(info.map, GridMap)
