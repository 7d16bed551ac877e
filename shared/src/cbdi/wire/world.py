"""Wire types of the shared world: clock, actions, percepts, snapshots, statistics.

Cells are `(x, y)` with x the column and y the row of a grid world's map. A domain's
simulator fills them (`cbdi.simulator`): its items, people and statistics by name.
Times are simulated seconds (the domain's time units); an epoch lasts `epoch_duration`.
"""

from __future__ import annotations

from typing import Annotated, Literal

import msgspec

from cbdi.wire.base import Message
from cbdi.wire.fields import (
    MAX_ITEMS,
    AgentName,
    Atom,
    Cell,
    Count,
    Epoch,
    Finite,
    Id,
    Many,
    NonNegative,
    Symbol,
    Text,
)

__all__ = [
    "ActionOutcome",
    "ActionReply",
    "ActionRequest",
    "AgentStats",
    "AgentView",
    "Cell",
    "ClockRequest",
    "EpochAck",
    "ItemView",
    "MapLayer",
    "MapLink",
    "MapPlace",
    "MapView",
    "OutcomeStatus",
    "Percept",
    "PersonView",
    "Sensed",
    "StatsRequest",
    "Tick",
    "WorldInfo",
    "WorldInfoRequest",
    "WorldSnapshot",
    "WorldStats",
]

Pose = tuple[Finite, Finite]

OutcomeStatus = Literal["succeeded", "failed"]


class Tick(Message, frozen=True, tag="cbdi.world.Tick/1"):
    """Publish the world's clock once per epoch: the simulated clock follows this."""

    epoch: Count
    time: NonNegative
    epoch_duration: Annotated[float, msgspec.Meta(gt=0.0, le=1e9)]
    speed: NonNegative
    lockstep: bool


class ActionRequest(Message, frozen=True, tag="cbdi.world.ActionRequest/1"):
    """Ask the world (or a performer) to start an action for `agent`.

    With `args`, `action` is a grounded PDDL action, as an executor sends it: the world's
    simulator performs it, or a performer carries it out. Without, it is one of a
    simulator's own primitive actions, with a `target` cell or an `item` as that
    simulator documents (a scripted robot sends them). `duration` is the plan's (0: not
    given).
    """

    agent: AgentName
    action: Symbol
    request_id: Symbol
    target: Cell | None = None
    item: Symbol | None = None
    args: Annotated[list[Symbol], msgspec.Meta(max_length=32)] = []
    duration: NonNegative = 0.0


class ActionReply(Message, frozen=True, tag="cbdi.world.ActionReply/1"):
    """Answer an `ActionRequest` at once: accepted (with when it ends) or rejected and why."""

    request_id: Id
    accepted: bool
    reason: Text = ""
    starts_at: Finite = 0.0
    ends_at: Finite = 0.0


class ActionOutcome(Message, frozen=True, tag="cbdi.world.ActionOutcome/1"):
    """Report how an accepted action ended: `succeeded` or `failed` with a reason."""

    agent: AgentName
    request_id: Symbol
    action: Symbol
    status: OutcomeStatus
    reason: Text
    epoch: Count
    time: NonNegative
    target: Cell | None = None
    item: Symbol | None = None


class ItemView(Message, frozen=True, tag="cbdi.world.ItemView/1"):
    """One item lying on a cell; `known` says whether agents knew of it from the start."""

    name: Symbol
    cell: Cell
    known: bool = True


# What the world had published on an agent's keys when it sent the agent's percepts (the
# last of its epoch): the count of its outcomes key, cumulative (as `EpochAck.sent`). A
# gate that has fewer waits for the rest: the bus may recover one key's samples later than
# another's (after a router restart), so arrival order across keys proves nothing.
WorldSent = Annotated[dict[Symbol, Count], msgspec.Meta(max_length=8)]


class Percept(Message, frozen=True):
    """What one agent senses in one epoch: the base of every message a world publishes
    on an agent's percepts key, `Sensed` or a domain's own (registered in entry-point
    group `cbdi.percepts`, `cbdi.plugins.percept_types`). The lockstep gates and the
    services read only these fields; a domain's knowledge reads the rest. `sent`: see
    `WorldSent` (the world service fills it in)."""

    agent: AgentName
    epoch: Count
    time: NonNegative
    sent: WorldSent = {}


class Sensed(Percept, frozen=True, tag="cbdi.world.Sensed/1"):
    """What one agent senses this epoch, as belief changes: any simulator's percepts.

    `instances` are objects first seen (name -> PDDL type), `add` the ground atoms sensed
    true, `delete` those sensed false, `fluents` function values read. The generic
    knowledge (`cbdi.literals.LiteralKnowledge`) applies them in that order; an atom
    neither added nor deleted keeps what the agent believed. `sent`: see `WorldSent`.
    """

    instances: Annotated[dict[Symbol, Symbol], msgspec.Meta(max_length=MAX_ITEMS)] = {}
    add: Many[Atom] = []
    delete: Many[Atom] = []
    fluents: Many[tuple[Atom, Finite]] = []


class AgentView(Message, frozen=True, tag="cbdi.world.AgentView/1"):
    """One robot in a snapshot: logical cell, continuous pose, what it carries (`load`:
    the items it has taken off the map) and its current action."""

    name: AgentName
    cell: Cell
    pose: Pose
    load: Many[Symbol] = []
    action: Id = ""


class PersonView(Message, frozen=True, tag="cbdi.world.PersonView/1"):
    """One person in a snapshot."""

    name: Symbol
    cell: Cell
    pose: Pose


class WorldSnapshot(Message, frozen=True, tag="cbdi.world.WorldSnapshot/1"):
    """Everything that moves, published every epoch for viewers and recorders: robots,
    people (moving obstacles), the items lying on the map and those whose job is done
    (`completed`: taken off the map for good, a delivered parcel, say)."""

    epoch: Count
    time: NonNegative
    agents: Many[AgentView]
    people: Many[PersonView]
    items: Many[ItemView]
    completed: Many[Symbol]


class ClockRequest(Message, frozen=True, tag="cbdi.world.ClockRequest/1"):
    """Ask for the world's latest tick (an `ErrorReply` `not_started` before epoch 0): a
    member restarted mid-run joins at the epoch under way."""


class WorldInfoRequest(Message, frozen=True, tag="cbdi.world.WorldInfoRequest/1"):
    """Ask for the static part of the world (map geometry)."""


Colour = tuple[
    Annotated[int, msgspec.Meta(ge=0, le=255)],
    Annotated[int, msgspec.Meta(ge=0, le=255)],
    Annotated[int, msgspec.Meta(ge=0, le=255)],
]


class MapLayer(Message, frozen=True, tag="cbdi.world.MapLayer/1"):
    """One static layer of a map as the views draw it: cells (walls, drop-off places,
    chargers), each a box `size` cells wide in `colour` (rerun, at `world/map/<name>`)
    and the character `glyph` (text), with a label per cell or none."""

    name: Symbol
    cells: Many[Cell]
    labels: Many[Symbol] = []
    glyph: Annotated[str, msgspec.Meta(pattern="^[!-~]$")] = "#"
    colour: Colour = (60, 60, 60)
    size: Annotated[float, msgspec.Meta(gt=0.0, le=1.0)] = 1.0


class MapPlace(Message, frozen=True, tag="cbdi.world.MapPlace/1"):
    """One place of a map that is a graph (a room, a bed of plants, a cell its PDDL
    names): where the views draw it (`at`, in cells: x the column, y the row, within
    the view), the character `glyph` (text) and its name (a label in rerun)."""

    name: Symbol
    at: Pose
    glyph: Annotated[str, msgspec.Meta(pattern="^[!-~]$")] = "o"


class MapLink(Message, frozen=True, tag="cbdi.world.MapLink/1"):
    """A link between two places of the view, either way: a line the views draw."""

    a: Symbol
    b: Symbol


MAX_PLACES = 100_000  # the floor cells of a 300x300 map, each a place


class MapView(Message, frozen=True, tag="cbdi.world.MapView/1"):
    """How the views draw a map: its size (cells), static layers of cells, and, for a
    map that is a graph, its places and the links between them. What the cells and
    places mean is the domain's (its knowledge reads `WorldInfo.map`). Every place lies
    within the size, names are unique, and a link joins two different places."""

    width: Annotated[int, msgspec.Meta(ge=1, le=10_000)]
    height: Annotated[int, msgspec.Meta(ge=1, le=10_000)]
    layers: Annotated[list[MapLayer], msgspec.Meta(max_length=64)] = []
    places: Annotated[list[MapPlace], msgspec.Meta(max_length=MAX_PLACES)] = []
    links: Annotated[list[MapLink], msgspec.Meta(max_length=4 * MAX_PLACES)] = []

    def __post_init__(self) -> None:
        names: set[str] = set()
        for p in self.places:
            x, y = p.at
            if not (0.0 <= x <= self.width and 0.0 <= y <= self.height):
                raise ValueError(f"place {p.name} at {x:g},{y:g} is off the map")
            if p.name in names:
                raise ValueError(f"place {p.name} appears twice")
            names.add(p.name)
        for link in self.links:
            if link.a == link.b or link.a not in names or link.b not in names:
                raise ValueError(f"link {link.a}-{link.b} does not join two places of the map")


# A domain's own map, encoded by its simulator: one message of the domain's own type (the
# grid's `cbdi.recycling.GridMap/1`), which only the domain's code decodes.
DomainMap = Annotated[bytes, msgspec.Meta(max_length=64 * 1024 * 1024)]


class WorldInfo(Message, frozen=True, tag="cbdi.world.WorldInfo/1"):
    """The static part of the world, what every domain has: the agents, the epoch's
    length, action durations, the static beliefs (`instances`, `facts`, `fluents`), how
    views draw the map (`view`, if it has a floor of cells) and the domain's own map
    (`map`, read only by the domain's code)."""

    map_name: Text
    agents: Many[AgentName]
    epoch_duration: Annotated[float, msgspec.Meta(gt=0.0, le=1e9)]
    durations: Annotated[dict[Symbol, NonNegative], msgspec.Meta(max_length=1000)]
    known_items: Many[ItemView] = []  # items agents know of at the start
    # The members (`agent/component`) the start barrier, and in lockstep every epoch,
    # waits for.
    members: Many[Symbol] = []
    lockstep: bool = False
    actions: Many[Symbol] = []  # the PDDL actions the world performs (its simulator's)
    # What the map tells every agent at the start (a simulator's static beliefs): objects
    # (name -> PDDL type), ground atoms and function values.
    instances: Annotated[dict[Symbol, Symbol], msgspec.Meta(max_length=MAX_ITEMS)] = {}
    facts: Many[Atom] = []
    fluents: Many[tuple[Atom, Finite]] = []
    simulator: Id = ""  # the simulator's name (entry point cbdi.simulators)
    view: MapView | None = None
    map: DomainMap = b""


ACK_STAGES = ("ready", "beliefs", "done")


class EpochAck(Message, frozen=True, tag="cbdi.world.EpochAck/1"):
    """Acknowledge an epoch (lockstep): `component` of `agent` has handled epoch `epoch`.

    `stage` is `done` (everything of the epoch handled, its messages sent), `beliefs`
    (the scheduler's first half: beliefs and commands out, the planner may start) or
    `ready` (epoch -1: alive, subscribed, waiting for epoch 0; the start barrier).
    `sent` is what the component had published by then, per key (cumulative counts, the
    `seq` of its last message on that key): a receiver that has fewer of a key's messages
    waits for the rest, so nothing of epoch k arrives after the next epoch starts.
    """

    agent: AgentName
    epoch: Epoch
    component: AgentName = "executor"
    stage: Literal["ready", "beliefs", "done"] = "done"
    sent: Annotated[dict[Symbol, Count], msgspec.Meta(max_length=64)] = {}


class AgentStats(Message, frozen=True, tag="cbdi.world.AgentStats/1"):
    """Counters for one agent: actions that failed and requests refused, time busy, and
    the simulator's own counters in `counts`, by name (the grid's moves, blocked moves,
    contacts, pickups and recycled items; courier's count of each action)."""

    agent: AgentName
    failed: Count = 0
    rejected: Count = 0
    busy: NonNegative = 0.0  # simulated seconds in actions that ended (the rest is idle)
    counts: Annotated[dict[Symbol, Count], msgspec.Meta(max_length=256)] = {}


class StatsRequest(Message, frozen=True, tag="cbdi.world.StatsRequest/1"):
    """Ask for statistics, of one agent or (agent empty) of all."""

    agent: Id = ""


class WorldStats(Message, frozen=True, tag="cbdi.world.WorldStats/1"):
    """Per-agent counters and the simulator's totals (by name) at `epoch`; `done` when
    the run's goals are all met."""

    epoch: Count
    time: NonNegative
    agents: Many[AgentStats]
    done: bool = False
    totals: Annotated[dict[Symbol, Count], msgspec.Meta(max_length=256)] = {}
