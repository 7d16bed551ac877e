"""Wire types of the shared world: clock, actions, percepts, snapshots, statistics.

Cells are `(x, y)` with x the column and y the row, as in the paper's `c_X_Y` names.
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
    "PERCEPTS",
    "ActionOutcome",
    "ActionReply",
    "ActionRequest",
    "AgentStats",
    "AgentView",
    "BinView",
    "Cell",
    "ClockRequest",
    "EpochAck",
    "LitterView",
    "OutcomeStatus",
    "Percepts",
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

# Action names the world accepts; durations come from the recycling domain.
ACTIONS = ("move", "pickup", "recycle")


class Tick(Message, frozen=True, tag="cbdi.world.Tick/1"):
    """Publish the world's clock once per epoch: the simulated clock follows this."""

    epoch: Count
    time: NonNegative
    epoch_duration: Annotated[float, msgspec.Meta(gt=0.0, le=1e9)]
    speed: NonNegative
    lockstep: bool


class ActionRequest(Message, frozen=True, tag="cbdi.world.ActionRequest/1"):
    """Ask the world (or a performer) to start an action for `agent`.

    With `args`, `action` is a grounded PDDL action, as an executor sends it: the world
    binds it to what it simulates (its domain's binding, `cbdi.bindings`), a performer
    carries it out. Without, it is one of the grid world's own actions: `move` needs
    `target` (a 4-adjacent cell); `pickup` takes the litter in the agent's cell (`item`
    optional, to pick a specific one); `recycle` puts held litter (`item`, or the first
    held) into a bin next to the agent. `duration` is the plan's (0: not given).
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


class LitterView(Message, frozen=True, tag="cbdi.world.LitterView/1"):
    """One litter item lying on a cell; `known` says whether agents knew it from the start."""

    name: Symbol
    cell: Cell
    known: bool = True


class Percepts(Message, frozen=True, tag="cbdi.world.Percepts/1"):
    """What one agent senses this epoch in the (2d+1)x(2d+1) square around it.

    `free` cells are inside the map and hold no wall, bin, person or agent; `blocked` are
    the other in-map cells of the square (the agent's own cell is reported as blocked by
    itself only in `position`). `litter` lists the items lying in the square.
    """

    agent: AgentName
    epoch: Count
    time: NonNegative
    position: Cell
    depth: Annotated[int, msgspec.Meta(ge=0, le=1000)]
    free: Many[Cell]
    blocked: Many[Cell]
    litter: Many[LitterView]
    holding: Many[Symbol]


class Sensed(Message, frozen=True, tag="cbdi.world.Sensed/1"):
    """What one agent senses this epoch, as belief changes: any simulator's percepts.

    `instances` are objects first seen (name -> PDDL type), `add` the ground atoms sensed
    true, `delete` those sensed false, `fluents` function values read. The generic
    knowledge (`cbdi.literals.LiteralKnowledge`) applies them in that order; an atom
    neither added nor deleted keeps what the agent believed.
    """

    agent: AgentName
    epoch: Count
    time: NonNegative
    instances: Annotated[dict[Symbol, Symbol], msgspec.Meta(max_length=MAX_ITEMS)] = {}
    add: Many[Atom] = []
    delete: Many[Atom] = []
    fluents: Many[tuple[Atom, Finite]] = []


# The percept messages a world publishes (the grid world's, any simulator's).
PERCEPTS = (Percepts, Sensed)


class AgentView(Message, frozen=True, tag="cbdi.world.AgentView/1"):
    """One robot in a snapshot: logical cell, continuous pose, load and current action."""

    name: AgentName
    cell: Cell
    pose: Pose
    holding: Many[Symbol]
    action: Id = ""


class PersonView(Message, frozen=True, tag="cbdi.world.PersonView/1"):
    """One person in a snapshot."""

    name: Symbol
    cell: Cell
    pose: Pose


class BinView(Message, frozen=True, tag="cbdi.world.BinView/1"):
    """One bin."""

    name: Symbol
    cell: Cell


class WorldSnapshot(Message, frozen=True, tag="cbdi.world.WorldSnapshot/1"):
    """Everything that moves, published every epoch for viewers and recorders."""

    epoch: Count
    time: NonNegative
    agents: Many[AgentView]
    people: Many[PersonView]
    litter: Many[LitterView]
    recycled: Many[Symbol]


class ClockRequest(Message, frozen=True, tag="cbdi.world.ClockRequest/1"):
    """Ask for the world's latest tick (an `ErrorReply` `not_started` before epoch 0): a
    member restarted mid-run joins at the epoch under way."""


class WorldInfoRequest(Message, frozen=True, tag="cbdi.world.WorldInfoRequest/1"):
    """Ask for the static part of the world (map geometry)."""


class WorldInfo(Message, frozen=True, tag="cbdi.world.WorldInfo/1"):
    """The static part of the world: size, walls, bins, agents and their sensing depth."""

    map_name: Text
    width: Annotated[int, msgspec.Meta(ge=1, le=10_000)]
    height: Annotated[int, msgspec.Meta(ge=1, le=10_000)]
    walls: Many[Cell]
    bins: Many[BinView]
    agents: Many[AgentName]
    detection_depth: Annotated[dict[AgentName, Count], msgspec.Meta(max_length=10_000)]
    capacity: Count
    epoch_duration: Annotated[float, msgspec.Meta(gt=0.0, le=1e9)]
    durations: Annotated[dict[Symbol, NonNegative], msgspec.Meta(max_length=1000)]
    known_litter: Many[LitterView] = []  # litter agents know of at the start
    # The members (`agent/component`) the start barrier, and in lockstep every epoch,
    # waits for.
    members: Many[Symbol] = []
    lockstep: bool = False
    actions: Many[Symbol] = []  # the PDDL actions the world performs (its binding's)
    # What the map tells every agent at the start (a simulator's static beliefs): objects
    # (name -> PDDL type), ground atoms and function values.
    instances: Annotated[dict[Symbol, Symbol], msgspec.Meta(max_length=MAX_ITEMS)] = {}
    facts: Many[Atom] = []
    fluents: Many[tuple[Atom, Finite]] = []
    simulator: Id = ""  # the simulator's name (cbdi.simulators; "" the grid world)


ACK_STAGES = ("ready", "beliefs", "done")


class EpochAck(Message, frozen=True, tag="cbdi.world.EpochAck/1"):
    """Acknowledge an epoch (lockstep): `component` of `agent` has handled epoch `epoch`.

    `stage` is `done` (everything of the epoch handled, its messages sent), `beliefs`
    (the scheduler's first half: beliefs and commands out, the planner may start) or
    `ready` (epoch -1: alive, subscribed, waiting for epoch 0; the start barrier).
    `sent` is what the component had published by then, per key (cumulative counts, the
    `seq` of its last message on that key): a receiver holding fewer of a key's messages
    waits for the rest, so nothing of epoch k arrives after the next epoch starts.
    """

    agent: AgentName
    epoch: Epoch
    component: AgentName = "executor"
    stage: Literal["ready", "beliefs", "done"] = "done"
    sent: Annotated[dict[Symbol, Count], msgspec.Meta(max_length=64)] = {}


class AgentStats(Message, frozen=True, tag="cbdi.world.AgentStats/1"):
    """Counters for one agent, the paper's metric (moves) first."""

    agent: AgentName
    moves: Count = 0
    pickups: Count = 0
    recycled: Count = 0
    blocked: Count = 0
    failed: Count = 0
    rejected: Count = 0
    contacts: Count = 0
    busy: NonNegative = 0.0  # simulated seconds in actions that ended (the rest is idle)
    # A simulator's own counters (deliveries, charges, ...), by name.
    counts: Annotated[dict[Symbol, Count], msgspec.Meta(max_length=256)] = {}


class StatsRequest(Message, frozen=True, tag="cbdi.world.StatsRequest/1"):
    """Ask for statistics, of one agent or (agent empty) of all."""

    agent: Id = ""


class WorldStats(Message, frozen=True, tag="cbdi.world.WorldStats/1"):
    """Per-agent counters and the totals at `epoch` (the grid world's litter totals, a
    simulator's `totals`); `done` when the run's goals are all met."""

    epoch: Count
    time: NonNegative
    agents: Many[AgentStats]
    litter_on_ground: Count = 0
    litter_held: Count = 0
    litter_recycled: Count = 0
    litter_spawned: Count = 0
    done: bool = False
    totals: Annotated[dict[Symbol, Count], msgspec.Meta(max_length=256)] = {}
