"""The grid world's percepts: the square a robot senses around it (`Percepts`).

A wire type of this domain, registered in entry-point group `cbdi.percepts`, so the
generic services decode it on an agent's percepts key and pass it on as a `Percept`
(its agent, epoch, time and `sent` are all they read); the recycling knowledge
(`cbdi_recycling.knowledge`) and the scripted robot read the rest.
"""

from __future__ import annotations

from typing import Annotated

import msgspec

from cbdi.wire.base import Message
from cbdi.wire.fields import AgentName, Cell, Many, Symbol
from cbdi.wire.world import ItemView, Percept

__all__ = ["AgentSeen", "Percepts"]


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
